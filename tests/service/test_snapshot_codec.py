"""The snapshot body codec: exact, deterministic, and refusing a body that does not fit."""

from __future__ import annotations

import struct
from typing import Any

import orjson
import pytest
import zstandard
from hypothesis import given, settings
from hypothesis import strategies as st

from core.evolve import fold
from core.state import SceneState
from service.store.snapshot_codec import SNAPSHOT_HEADER, decode_snapshot, encode_snapshot
from tests.core.replay_runs import live_run, step


@settings(max_examples=30, deadline=None)
@given(st.lists(step, min_size=1, max_size=10), st.data())
def test_decoded_snapshot_equals_the_state_and_folds_on_alike(
    steps: list[dict[str, Any]], data: st.DataObject
) -> None:
    log, live = live_run(steps)
    cut = data.draw(st.integers(min_value=0, max_value=len(log)))
    prefix = fold(SceneState(), log[:cut])
    body = encode_snapshot(prefix)
    decoded = decode_snapshot(body)
    assert decoded.to_dict() == prefix.to_dict()
    assert encode_snapshot(decoded) == body  # deterministic: `pbdag rebuild` compares bytes
    assert fold(decoded, log[cut:]).to_dict() == live.to_dict()


def _parts(body: bytes) -> tuple[dict[str, Any], bytes]:
    raw = zstandard.ZstdDecompressor().decompress(body)
    (length,) = SNAPSHOT_HEADER.unpack_from(raw)
    start = SNAPSHOT_HEADER.size
    return orjson.loads(raw[start : start + length]), raw[start + length :]


def _body(header: dict[str, Any], floats: bytes) -> bytes:
    text = orjson.dumps(header)
    return zstandard.ZstdCompressor().compress(SNAPSHOT_HEADER.pack(len(text)) + text + floats)


def test_float_arrays_leave_the_json_and_come_back_exactly() -> None:
    log, live = live_run(
        [{"mug_1": 0, "book_1": 1, "detect": {"mug_1", "book_1"}, "occlude": False}]
    )
    header, floats = _parts(encode_snapshot(live))
    counts = [(t["recent_centers"], t["embedding_sum"]) for t in header["tracks"]]
    assert all(isinstance(c, int) for pair in counts for c in pair if c is not None)
    assert len(floats) == 8 * sum(c or 0 for pair in counts for c in pair)
    assert decode_snapshot(_body(header, floats)).to_dict() == live.to_dict()
    assert len(log) > 1


def test_a_float_block_that_does_not_fit_its_tracks_is_refused() -> None:
    _log, live = live_run([{"mug_1": 0, "book_1": None, "detect": {"mug_1"}, "occlude": False}])
    header, floats = _parts(encode_snapshot(live))
    with pytest.raises(ValueError, match="does not fit"):
        decode_snapshot(_body(header, floats[:-8]))
    with pytest.raises(ValueError, match="does not fit"):
        decode_snapshot(_body(header, floats + struct.pack("<d", 1.0)))


def test_a_track_whose_centers_are_not_triples_is_refused() -> None:
    _log, live = live_run(
        [{"mug_1": 0, "book_1": 1, "detect": {"mug_1", "book_1"}, "occlude": False}]
    )
    header, floats = _parts(encode_snapshot(live))
    first, second = header["tracks"][0], header["tracks"][1]
    assert first["recent_centers"] >= 3 and second["recent_centers"] >= 3
    first["recent_centers"] -= 1  # the total still fits the block; the split does not
    second["recent_centers"] += 1
    with pytest.raises(ValueError, match="center values"):
        decode_snapshot(_body(header, floats))
