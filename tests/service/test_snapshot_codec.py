"""The snapshot body codec: exact, deterministic, and refusing a body that does not fit."""

from __future__ import annotations

import dataclasses
import math
import struct
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from bench.perf_common import synthetic_events
from core.events import SceneCreated
from core.evolve import evolve, fold
from core.fixture_map import VoxelMap
from core.params import Params
from core.state import SceneState, Track
from service.store.snapshot_codec import (
    SNAPSHOT_VERSION,
    SNAPSHOT_VERSION_ROWS,
    decode_snapshot,
    encode_snapshot,
)
from tests.core.replay_runs import live_run, step
from tests.service.snapshot_bodies import body_of, parts, rows_body


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
    older = decode_snapshot(rows_body(prefix), SNAPSHOT_VERSION_ROWS)  # version 3 still read
    assert older == decoded and encode_snapshot(older) == body


def _benchmark_state(events: int) -> SceneState:
    """The as_of benchmark's scene (500 tracks with 64-value appearance sums, misses)."""
    created = SceneCreated(name="bench", params=Params().to_dict())
    return fold(evolve(SceneState(), created), synthetic_events(events))


def test_a_realistic_state_comes_back_exactly_in_both_versions() -> None:
    state = _benchmark_state(3000)
    assert len(state.tracks) == 500
    floats = [
        value
        for track in state.tracks.values()
        for value in (*(v for c in track.recent_centers for v in c), *(track.embedding_sum or ()))
    ]
    assert len(floats) > 30_000 and all(math.isfinite(v) for v in floats)
    body = encode_snapshot(state)
    for decoded in (
        decode_snapshot(body),
        decode_snapshot(rows_body(state), SNAPSHOT_VERSION_ROWS),
    ):
        assert decoded == state  # every field of every track, float for float
        assert decoded.to_dict() == state.to_dict()
        assert encode_snapshot(decoded) == body
        tail = list(synthetic_events(3400))[3000:]
        assert fold(decoded, tail).to_dict() == fold(state, tail).to_dict()


def test_float_arrays_leave_the_json_and_come_back_exactly() -> None:
    log, live = live_run(
        [{"mug_1": 0, "book_1": 1, "detect": {"mug_1", "book_1"}, "occlude": False}]
    )
    header, floats = parts(encode_snapshot(live))
    columns = header["tracks"]
    counts = list(zip(columns["recent_centers"], columns["embedding_sum"], strict=True))
    assert len(counts) == len(live.tracks) == 2
    assert all(isinstance(c, int) for pair in counts for c in pair if c is not None)
    assert len(floats) == 8 * sum(c or 0 for pair in counts for c in pair)
    assert decode_snapshot(body_of(header, floats)).to_dict() == live.to_dict()
    assert len(log) > 1


def _two_tracks() -> tuple[dict[str, Any], bytes]:
    _log, live = live_run(
        [{"mug_1": 0, "book_1": 1, "detect": {"mug_1", "book_1"}, "occlude": False}]
    )
    return parts(encode_snapshot(live))


def test_a_float_block_that_does_not_fit_its_tracks_is_refused() -> None:
    header, floats = _two_tracks()
    with pytest.raises(ValueError, match="does not fit"):
        decode_snapshot(body_of(header, floats[:-8]))
    with pytest.raises(ValueError, match="does not fit"):
        decode_snapshot(body_of(header, floats + struct.pack("<d", 1.0)))


def test_a_track_whose_centers_are_not_triples_is_refused() -> None:
    header, floats = _two_tracks()
    counts = header["tracks"]["recent_centers"]
    assert counts[0] >= 3 and counts[1] >= 3
    counts[0] -= 1  # the total still fits the block; the split does not
    counts[1] += 1
    with pytest.raises(ValueError, match="center values"):
        decode_snapshot(body_of(header, floats))


def test_a_corrupt_body_is_refused() -> None:
    header, floats = _two_tracks()
    body = body_of(header, floats)
    with pytest.raises(ValueError, match="not zstandard"):
        decode_snapshot(body[: len(body) // 2])
    missing = {**header, "tracks": {k: v for k, v in header["tracks"].items() if k != "box"}}
    with pytest.raises(ValueError, match="track fields"):
        decode_snapshot(body_of(missing, floats))
    short = {**header, "tracks": {**header["tracks"], "pinned": [False]}}
    with pytest.raises(ValueError, match="differ in length"):
        decode_snapshot(body_of(short, floats))
    ids = header["tracks"]["track_id"]
    twice = {**header, "tracks": {**header["tracks"], "track_id": [ids[0], ids[0]]}}
    with pytest.raises(ValueError, match="repeat an id"):
        decode_snapshot(body_of(twice, floats))
    with pytest.raises(ValueError, match="not supported"):
        decode_snapshot(body, SNAPSHOT_VERSION + 1)


def _with_voxels(count: int, width: int) -> SceneState:
    """The benchmark's scene with a fixture voxel map of `count` voxels and `width` classes."""
    rng = np.random.default_rng(3)
    keys = np.unique(rng.integers(0, 2**40, size=count * 2))[:count].astype(np.int64)
    voxels = VoxelMap(keys, rng.integers(1, 50, size=count), rng.random((count, width)) * 9)
    return dataclasses.replace(_benchmark_state(600), voxels=voxels)


def test_the_voxel_map_comes_back_exactly_as_arrays_after_the_floats() -> None:
    state = _with_voxels(5000, 7)
    body = encode_snapshot(state)
    header, tail = parts(body)
    assert header["voxels"] == {"count": 5000, "width": 7}  # no voxel in the JSON
    assert len(tail) >= 8 * 5000 * (2 + 7)
    decoded = decode_snapshot(body)
    assert decoded.voxels == state.voxels and decoded.voxels.sums.shape == (5000, 7)
    assert decoded.to_dict() == state.to_dict()
    assert encode_snapshot(decoded) == body
    empty = decode_snapshot(encode_snapshot(_benchmark_state(600)))
    assert len(empty.voxels) == 0 and empty.voxels.sums.shape == (0, 0)


def test_a_voxel_map_that_does_not_fit_or_is_not_sorted_is_refused() -> None:
    header, tail = parts(encode_snapshot(_with_voxels(40, 3)))
    with pytest.raises(ValueError, match="does not fit"):
        decode_snapshot(body_of({**header, "voxels": {"count": 10**6, "width": 3}}, tail))
    with pytest.raises(ValueError, match="shape"):
        decode_snapshot(body_of({**header, "voxels": [[0, 0, 0, 1, [1.0]]]}, tail))
    with pytest.raises(ValueError, match="shape"):
        decode_snapshot(body_of({**header, "voxels": {"count": -1, "width": 3}}, tail))
    floats = len(tail) - 8 * 40 * 5
    keys = bytearray(tail)
    keys[floats : floats + 16] = keys[floats + 8 : floats + 16] + keys[floats : floats + 8]
    with pytest.raises(ValueError, match="sorted"):
        decode_snapshot(body_of(header, bytes(keys)))


def test_a_decoded_track_makes_its_float_fields_only_when_they_are_read() -> None:
    state = _benchmark_state(1200)
    decoded = decode_snapshot(encode_snapshot(state))
    first, second, third = list(state.tracks)[:3]
    track = decoded.tracks[first]
    assert {"recent_centers", "embedding_sum"}.isdisjoint(vars(track))  # still in the block
    assert track.recent_centers == state.tracks[first].recent_centers
    assert "recent_centers" in vars(track) and "embedding_sum" not in vars(track)
    assert track.embedding_sum == state.tracks[first].embedding_sum
    assert track.embedding_sum is not None and len(track.embedding_sum) == 64
    # A track evolved from one still packed is packed alike, until both fields are its own.
    moved = decoded.tracks[second].evolved(center=(1.0, 2.0, 3.0))
    assert "_packed" in vars(moved) and "recent_centers" not in vars(moved)
    assert moved.recent_centers == state.tracks[second].recent_centers
    replaced = decoded.tracks[third].evolved(recent_centers=(), embedding_sum=None)
    assert "_packed" not in vars(replaced)
    assert (replaced.recent_centers, replaced.embedding_sum) == ((), None)
    with pytest.raises(AttributeError, match="recent_centers"):
        _ = Track.__new__(Track).recent_centers  # neither packed nor set: no such field yet
