"""Snapshot bodies as older code wrote them, and the parts of a current one, for the tests."""

from __future__ import annotations

from typing import Any

import numpy as np
import orjson
import zstandard

from core.state import SceneState
from service.store.snapshot_codec import FLOAT_BLOCKS, SNAPSHOT_HEADER


def rows_body(state: SceneState) -> bytes:
    """A version 3 body (one JSON object per track), as the encoder wrote it before version 4."""
    record = state.to_dict()
    blocks: dict[str, list[Any]] = {key: [] for key in FLOAT_BLOCKS}
    for track in record["tracks"]:
        for key in FLOAT_BLOCKS:
            if track[key] is not None:
                values = np.asarray(track[key], dtype="<f8").reshape(-1)
                track[key] = len(values)
                blocks[key].append(values)
    arrays = [values for key in FLOAT_BLOCKS for values in blocks[key]]
    floats = np.concatenate(arrays).tobytes() if arrays else b""
    header = orjson.dumps(record)
    return zstandard.ZstdCompressor(level=1).compress(
        SNAPSHOT_HEADER.pack(len(header)) + header + floats
    )


def parts(body: bytes) -> tuple[dict[str, Any], bytes]:
    """A body's JSON record and its float block."""
    raw = zstandard.ZstdDecompressor().decompress(body)
    (length,) = SNAPSHOT_HEADER.unpack_from(raw)
    start = SNAPSHOT_HEADER.size
    return orjson.loads(raw[start : start + length]), raw[start + length :]


def body_of(record: dict[str, Any], floats: bytes) -> bytes:
    """A body from its JSON record and float block."""
    text = orjson.dumps(record)
    return zstandard.ZstdCompressor().compress(SNAPSHOT_HEADER.pack(len(text)) + text + floats)
