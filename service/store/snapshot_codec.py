"""The snapshot body: a scene state as compressed bytes, deterministic for equal states."""

from __future__ import annotations

import struct

import numpy as np
import numpy.typing as npt
import orjson
import zstandard

from core.state import SNAPSHOT_FORMAT_VERSION, SceneState

__all__ = ["SNAPSHOT_HEADER", "SNAPSHOT_VERSION", "decode_snapshot", "encode_snapshot"]

# Version 3 of the body codec (float arrays as one float64 block after the JSON), on top of the
# state's dict format; a change of either makes old snapshots unreadable, so they are replayed
# instead.
SNAPSHOT_VERSION = 100 * SNAPSHOT_FORMAT_VERSION + 3
FLOAT_BLOCKS = ("recent_centers", "embedding_sum")  # most of a snapshot's numbers
SNAPSHOT_HEADER = struct.Struct("<I")  # the length of the JSON part
SNAPSHOT_ZSTD_LEVEL = 1


def encode_snapshot(state: SceneState) -> bytes:
    """Compressed snapshot body; deterministic bytes for equal states.

    zstandard(u32 length, the state's JSON, float64 block). Each track's long float arrays
    (`FLOAT_BLOCKS`) leave the JSON, which keeps their length, for one exact little-endian
    float64 block after it: every track's recent centers, then every track's embedding sum, in
    track order. Parsing decimal text of ~80k floats, or inflating base64 of them under zlib,
    costs more than the rest of an as_of.
    """
    record = state.to_dict()
    blocks: dict[str, list[npt.NDArray[np.float64]]] = {key: [] for key in FLOAT_BLOCKS}
    for track in record["tracks"]:
        for key in FLOAT_BLOCKS:
            if track[key] is not None:
                values = np.asarray(track[key], dtype="<f8").reshape(-1)
                track[key] = len(values)
                blocks[key].append(values)
    header = orjson.dumps(record)
    arrays = [values for key in FLOAT_BLOCKS for values in blocks[key]]
    floats = np.concatenate(arrays).tobytes() if arrays else b""
    body = SNAPSHOT_HEADER.pack(len(header)) + header + floats
    return zstandard.ZstdCompressor(level=SNAPSHOT_ZSTD_LEVEL).compress(body)


def decode_snapshot(body: bytes) -> SceneState:
    """Inverse of `encode_snapshot`."""
    raw = zstandard.ZstdDecompressor().decompress(body)
    (length,) = SNAPSHOT_HEADER.unpack_from(raw)
    start = SNAPSHOT_HEADER.size
    record = orjson.loads(memoryview(raw)[start : start + length])
    floats: list[float] = np.frombuffer(raw, dtype="<f8", offset=start + length).tolist()
    tracks = record["tracks"]
    centers_total = sum(t["recent_centers"] or 0 for t in tracks)
    if centers_total % 3 or sum(t["embedding_sum"] or 0 for t in tracks) + centers_total != len(
        floats
    ):
        raise ValueError(f"snapshot float block of {len(floats)} values does not fit its tracks")
    coordinates = iter(floats[:centers_total])
    points = list(zip(coordinates, coordinates, coordinates, strict=True))  # in track order
    point, position = 0, centers_total
    for track in tracks:
        count = track["recent_centers"]
        if count is not None:
            if count < 0 or count % 3:
                raise ValueError(f"snapshot track {track['track_id']}: {count} center values")
            track["recent_centers"] = tuple(points[point : point + count // 3])
            point += count // 3
        count = track["embedding_sum"]
        if count is not None:
            track["embedding_sum"] = tuple(floats[position : position + count])
            position += count
    return SceneState.from_dict(record)
