"""The stored form of raw batches: the compact format gives the canonical JSON back byte for
byte, the JSON format of older data dirs still reads, and the blob stores delete."""

from __future__ import annotations

import base64
import hashlib
from pathlib import Path
from typing import Any

import orjson
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from api_schema import BatchIn
from codec.canonical import canonical_json
from codec.observations import decode_batch
from core.observation import Batch
from service.store.blobs import BlobNotFound, BlobStore, FileBlobStore, MemoryBlobStore
from service.store.raw_batches import (
    COMPACT_MARKER,
    SECTION_DEPTH,
    RawBatchUnreadable,
    decode_raw_batch,
    encode_raw_batch,
    raw_batch_format,
    raw_batch_parts,
)
from tests.wire_scenes import batch

JSON_SCALARS = (
    st.none()
    | st.booleans()
    | st.integers(min_value=-(2**63), max_value=2**63 - 1)
    | st.floats(allow_nan=False, allow_infinity=False)
    | st.text(max_size=20)
)
JSON_VALUES = st.recursive(
    JSON_SCALARS,
    lambda inner: (
        st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=8), inner, max_size=4)
    ),
    max_leaves=12,
)
# Canonical base64 of any bytes, or text that is not (bad padding bits, other characters).
DEPTH_TEXT = st.binary(max_size=300).map(lambda raw: base64.b64encode(raw).decode()) | st.text(
    max_size=30
)


@st.composite
def bodies(draw: st.DrawFn) -> dict[str, Any]:
    """Batch-shaped JSON: frames with a depth text among arbitrary other fields."""
    frames = []
    for _ in range(draw(st.integers(0, 3))):
        frame = draw(st.dictionaries(st.text(max_size=8), JSON_VALUES, max_size=3))
        depth = draw(st.dictionaries(st.text(max_size=8), JSON_VALUES, max_size=2))
        if draw(st.booleans()):
            depth["data"] = draw(DEPTH_TEXT)
        frame["depth"] = depth if draw(st.booleans()) else draw(JSON_VALUES)
        frames.append(frame)
    body = draw(st.dictionaries(st.text(max_size=8), JSON_VALUES, max_size=3))
    body.pop("__scene_id__", None)
    body["frames"] = frames
    body["batch_id"] = draw(st.text(min_size=1, max_size=20))
    return body


@settings(max_examples=300, deadline=None)
@given(body=bodies(), scene_id=st.text(max_size=30))
def test_compact_round_trip_gives_the_canonical_json_back(
    body: dict[str, Any], scene_id: str
) -> None:
    stored = encode_raw_batch(body, scene_id)
    assert raw_batch_format(stored) == "compact"
    assert decode_raw_batch(stored) == canonical_json(body)


def test_a_real_batch_round_trips_smaller_and_the_scene_is_in_the_blob() -> None:
    body = BatchIn.model_validate(batch("b1", 1)).model_dump(mode="json")
    canonical = canonical_json(body)
    stored = encode_raw_batch(body, "scene-a")
    assert stored.startswith(COMPACT_MARKER)
    assert decode_raw_batch(stored) == canonical
    # Binary depth and compression: well under the canonical JSON with base64 depth.
    assert len(stored) < 0.8 * len(canonical)
    # One batch in two scenes: two blobs, so a blob is never shared between scenes.
    assert encode_raw_batch(body, "scene-b") != stored
    assert decode_raw_batch(encode_raw_batch(body, "scene-b")) == canonical
    # The idempotency hash is still over the canonical content, whatever the blob.
    assert (
        hashlib.sha256(decode_raw_batch(stored)).hexdigest()
        == hashlib.sha256(canonical).hexdigest()
    )


def test_depth_text_that_is_not_canonical_base64_is_kept_as_text() -> None:
    """ "QR==" decodes to b"A" like "QQ==": storing the bytes would not give the text back."""
    body = BatchIn.model_validate(batch("b1", 1)).model_dump(mode="json")
    canonical_depth = body["frames"][0]["depth"]["data"]
    body["frames"] = [body["frames"][0], {**body["frames"][0], "frame_id": "other"}]
    body["frames"][1]["depth"] = {**body["frames"][1]["depth"], "data": "QR=="}
    stored = encode_raw_batch(body, "s")
    restored = orjson.loads(decode_raw_batch(stored))
    assert [f["depth"]["data"] for f in restored["frames"]] == [canonical_depth, "QR=="]
    assert decode_raw_batch(stored) == canonical_json(body)


def same_batch(a: Batch, b: Batch) -> bool:
    """Two decoded batches hold the same frames: ids, poses, depth and detections."""
    return a.batch_id == b.batch_id and all(
        (f.frame_id, f.timestamp, f.intrinsics) == (g.frame_id, g.timestamp, g.intrinsics)
        and (f.pose == g.pose).all()
        and f.depth.tobytes() == g.depth.tobytes()
        and [(d.label, d.score, d.mask.runs.tolist()) for d in f.detections]
        == [(d.label, d.score, d.mask.runs.tolist()) for d in g.detections]
        for f, g in zip(a.frames, b.frames, strict=True)
    )


def test_the_parts_of_a_stored_batch_decode_to_the_batch_its_json_decodes_to() -> None:
    """The worker's path (the body with its depth as bytes) and the canonical JSON's: the same
    batch, for two frames whose depth a compact blob keeps in sections, and for the JSON format
    of older data dirs."""
    body = BatchIn.model_validate(batch("b1", 1)).model_dump(mode="json")
    body["frames"].append({**body["frames"][0], "frame_id": "second"})
    for blob in (encode_raw_batch(body, "s"), canonical_json(body)):
        parts, depths = raw_batch_parts(blob)
        assert sorted(depths) == ([0, 1] if blob.startswith(COMPACT_MARKER) else [])
        assert all(parts["frames"][i]["depth"]["data"] == SECTION_DEPTH for i in depths)
        direct = decode_batch(BatchIn.model_validate_json(orjson.dumps(parts)), None, depths)
        whole = decode_batch(BatchIn.model_validate_json(decode_raw_batch(blob)))
        assert same_batch(direct, whole)
        assert direct.frames[0].depth.any()  # the depth itself, not the placeholder's


def test_depth_kept_as_text_in_a_compact_blob_is_decoded_from_the_text() -> None:
    body = BatchIn.model_validate(batch("b1", 1)).model_dump(mode="json")
    text = body["frames"][0]["depth"]["data"]
    # Not the canonical base64 of any bytes (a newline inside): the blob keeps it as text.
    body["frames"][0]["depth"]["data"] = text[:8] + "\n" + text[8:]
    parts, depths = raw_batch_parts(encode_raw_batch(body, "s"))
    assert depths == {} and parts["frames"][0]["depth"]["data"] == text[:8] + "\n" + text[8:]


def test_the_json_format_of_older_data_dirs_still_decodes() -> None:
    canonical = canonical_json(BatchIn.model_validate(batch("old", 2)).model_dump(mode="json"))
    assert raw_batch_format(canonical) == "json"
    assert decode_raw_batch(canonical) == canonical


@pytest.mark.parametrize(
    "blob",
    [
        b"",
        b"\x00garbage",
        COMPACT_MARKER + b"not zstandard",
        COMPACT_MARKER[:-1] + b"9" + b"{}",
    ],
)
def test_an_unreadable_blob_is_a_clear_error(blob: bytes) -> None:
    with pytest.raises(RawBatchUnreadable, match="cannot be read"):
        decode_raw_batch(blob)


def test_a_truncated_compact_blob_is_a_clear_error() -> None:
    import zstandard

    body = BatchIn.model_validate(batch("b1", 1)).model_dump(mode="json")
    payload = zstandard.ZstdDecompressor().decompress(
        encode_raw_batch(body, "s")[len(COMPACT_MARKER) :]
    )
    for cut in (3, 20, len(payload) - 1):
        broken = COMPACT_MARKER + zstandard.ZstdCompressor().compress(payload[:cut])
        with pytest.raises(RawBatchUnreadable, match="corrupt layout"):
            decode_raw_batch(broken)


@pytest.mark.parametrize("kind", ["file", "memory"])
def test_blob_stores_put_get_and_delete(kind: str, tmp_path: Path) -> None:
    store: BlobStore = FileBlobStore(tmp_path / "blobs") if kind == "file" else MemoryBlobStore()
    key = store.put(b"raw batch")
    other = store.put(b"another")
    assert key == hashlib.sha256(b"raw batch").hexdigest()
    assert store.get(key) == b"raw batch"
    assert store.delete(key) is True
    assert store.delete(key) is False  # idempotent
    with pytest.raises(BlobNotFound):
        store.get(key)
    assert store.get(other) == b"another"
    assert store.put(b"raw batch") == key and store.get(key) == b"raw batch"
