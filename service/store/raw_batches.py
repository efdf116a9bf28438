"""The stored form of a raw batch: compact (binary depth, zstandard) or, in older data dirs, JSON.

A batch's identity is the sha256 of its canonical JSON (`codec.canonical.content_sha256`), kept in
the queue row; the blob only has to give that canonical JSON back, byte for byte. Two formats,
told apart by their first bytes:

- **JSON** (written before the compact format): the canonical JSON itself, so it starts with `{`.
- **compact**: the marker `PBDAGRB1`, then one zstandard frame holding
  `u32 n` (the depth sections), `n x (u32 frame index, u64 length)`, `u32 skeleton length`,
  the skeleton, then the sections' bytes. The skeleton is the canonical JSON of the batch with
  the base64 text of each section's depth (`frames[i].depth.data`) emptied, plus the scene id
  under `SCENE_KEY`, so one batch posted to two scenes makes two blobs and a blob is never
  shared between scenes (which `pbdag gc` relies on). Depth whose base64 text is not the
  canonical encoding of its bytes stays as text in the skeleton, so the round trip is exact
  whatever the client sent.
"""

from __future__ import annotations

import base64
import binascii
import struct
from typing import Any

import orjson
import zstandard

from service.store.errors import StoreError

__all__ = [
    "COMPACT_MARKER",
    "SECTION_DEPTH",
    "RawBatchUnreadable",
    "decode_raw_batch",
    "encode_raw_batch",
    "raw_batch_format",
    "raw_batch_parts",
]

COMPACT_MARKER = b"PBDAGRB1"
SCENE_KEY = "__scene_id__"  # cannot clash: BatchIn has no such field and forbids none of its own
# Level 3: the depth (a PNG or noisy float32) barely compresses further at higher levels, and
# the JSON around it compresses as well at 3 as at 9 for a tenth of the time.
ZSTD_LEVEL = 3
# A decompressed blob larger than this is corrupt (the request body limit is far below it).
MAX_DECOMPRESSED_BYTES = 1 << 31

# The `depth.data` of a frame whose depth `raw_batch_parts` gives as bytes: valid base64 (of
# one zero byte), so that the body still passes the schema; never decoded.
SECTION_DEPTH = "AA=="

_COUNT = struct.Struct("<I")
_SECTION = struct.Struct("<IQ")


class RawBatchUnreadable(StoreError):
    """A stored raw batch that is neither format, or a corrupt compact blob."""

    def __init__(self, reason: str) -> None:
        super().__init__(f"the stored raw batch cannot be read: {reason}", None)


def raw_batch_format(blob: bytes) -> str:
    """ "compact", "json" or "unknown", from the blob's first bytes."""
    if blob.startswith(COMPACT_MARKER):
        return "compact"
    if blob[:1] == b"{":
        return "json"
    return "unknown"


def _canonical(body: dict[str, Any]) -> bytes:
    return orjson.dumps(body, option=orjson.OPT_SORT_KEYS)


def encode_raw_batch(body: dict[str, Any], scene_id: str) -> bytes:
    """The compact blob of a batch (`body` as `BatchIn.model_dump(mode="json")`) in a scene."""
    skeleton = dict(body)
    sections: list[tuple[int, bytes]] = []
    frames = body.get("frames")
    if isinstance(frames, list):
        skeleton_frames: list[Any] = []
        for index, frame in enumerate(frames):
            data = _depth_text(frame)
            raw = _canonical_base64(data) if data is not None else None
            if raw is None:
                skeleton_frames.append(frame)
                continue
            sections.append((index, raw))
            skeleton_frames.append({**frame, "depth": {**frame["depth"], "data": ""}})
        skeleton["frames"] = skeleton_frames
    if SCENE_KEY in skeleton:
        raise ValueError(f"a batch body may not hold {SCENE_KEY!r}")
    skeleton[SCENE_KEY] = scene_id
    text = _canonical(skeleton)
    parts = [_COUNT.pack(len(sections))]
    parts += [_SECTION.pack(index, len(raw)) for index, raw in sections]
    parts += [_COUNT.pack(len(text)), text]
    parts += [raw for _index, raw in sections]
    return COMPACT_MARKER + zstandard.ZstdCompressor(level=ZSTD_LEVEL).compress(b"".join(parts))


def raw_batch_parts(blob: bytes) -> tuple[dict[str, Any], dict[int, bytes]]:
    """A stored batch as its body and, by frame index, the depth bytes a compact blob keeps in
    sections; those frames' `depth.data` holds `SECTION_DEPTH`, a placeholder the schema admits.
    A JSON blob is its body whole, with no sections. The worker decodes the depth from these
    bytes rather than from their base64 (`codec.observations.decode_batch`)."""
    kind = raw_batch_format(blob)
    if kind == "json":
        try:
            body = orjson.loads(blob)
        except orjson.JSONDecodeError as error:
            raise RawBatchUnreadable(f"corrupt JSON ({error})") from error
        if not isinstance(body, dict):
            raise RawBatchUnreadable("the JSON is not an object")
        return body, {}
    if kind == "unknown":
        raise RawBatchUnreadable(f"unknown format (first bytes {blob[:8]!r})")
    try:
        payload = zstandard.ZstdDecompressor().decompress(
            blob[len(COMPACT_MARKER) :], max_output_size=MAX_DECOMPRESSED_BYTES
        )
    except zstandard.ZstdError as error:
        raise RawBatchUnreadable(f"corrupt compression ({error})") from error
    try:
        (count,) = _COUNT.unpack_from(payload, 0)
        offset = _COUNT.size
        sections = []
        for _ in range(count):
            sections.append(_SECTION.unpack_from(payload, offset))
            offset += _SECTION.size
        (text_length,) = _COUNT.unpack_from(payload, offset)
        offset += _COUNT.size
        skeleton = orjson.loads(payload[offset : offset + text_length])
        offset += text_length
        frames = skeleton["frames"]
        depths: dict[int, bytes] = {}
        for index, length in sections:
            raw = payload[offset : offset + length]
            if len(raw) != length:
                raise ValueError("truncated depth section")
            offset += length
            frames[index]["depth"]["data"] = SECTION_DEPTH
            depths[index] = raw
        if offset != len(payload):
            raise ValueError("trailing bytes")
        del skeleton[SCENE_KEY]
    except (struct.error, orjson.JSONDecodeError, KeyError, IndexError, TypeError) as error:
        raise RawBatchUnreadable(f"corrupt layout ({type(error).__name__}: {error})") from error
    except ValueError as error:
        raise RawBatchUnreadable(f"corrupt layout ({error})") from error
    return skeleton, depths


def decode_raw_batch(blob: bytes) -> bytes:
    """The canonical JSON of a stored batch, from either format."""
    if raw_batch_format(blob) == "json":
        return blob
    body, depths = raw_batch_parts(blob)
    for index, raw in depths.items():
        body["frames"][index]["depth"]["data"] = base64.b64encode(raw).decode("ascii")
    return _canonical(body)


def _depth_text(frame: Any) -> str | None:
    """`frame["depth"]["data"]` when it is text, else None."""
    if not isinstance(frame, dict):
        return None
    depth = frame.get("depth")
    if not isinstance(depth, dict):
        return None
    data = depth.get("data")
    return data if isinstance(data, str) else None


def _canonical_base64(text: str) -> bytes | None:
    """The bytes of `text` when encoding them gives `text` back exactly, else None."""
    try:
        raw = base64.b64decode(text, validate=True)
    except (binascii.Error, ValueError):
        return None
    return raw if base64.b64encode(raw).decode("ascii") == text else None
