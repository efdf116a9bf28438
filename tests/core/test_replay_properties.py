"""Properties of the fold: replay equals live state, snapshot + tail equals replay, prefixes hold."""

from __future__ import annotations

from functools import reduce
from typing import Any

import numpy as np
import orjson
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from core.event_records import event_from_record, event_to_record
from core.evolve import evolve, fold
from core.state import SceneState
from tests.core.replay_runs import live_run, step


@settings(max_examples=40, deadline=None)
@given(st.lists(step, min_size=1, max_size=14))
def test_replay_of_the_serialized_log_equals_the_live_state(steps: list[dict[str, Any]]) -> None:
    log, live = live_run(steps)
    records = orjson.loads(orjson.dumps([event_to_record(e) for e in log]))
    replayed = reduce(evolve, (event_from_record(r) for r in records), SceneState())
    assert replayed.to_dict() == live.to_dict()
    assert replayed.head_seq == len(log) - 1
    # The live state's columns were derived batch by batch from the previous ones; the
    # replayed state builds them from its tracks: the two must agree.
    assert "arrays" in live.__dict__ and "arrays" not in replayed.__dict__
    derived, built = live.arrays, replayed.arrays
    assert (derived.track_ids, derived.kinds) == (built.track_ids, built.kinds)
    for name in ("centers", "extents", "published", "gone", "missing", "visible_misses"):
        assert np.array_equal(getattr(derived, name), getattr(built, name)), name
    assert np.array_equal(derived.last_observed, built.last_observed, equal_nan=True)
    assert np.array_equal(derived.unpublished_tentative, built.unpublished_tentative)
    # Rows by id: handed on from batch to batch while the ids stay, built anew otherwise.
    assert derived.position == built.position == {t: r for r, t in enumerate(built.track_ids)}
    kinds = [kind == "object" for kind in built.kinds]
    assert derived.objects.tolist() == built.objects.tolist() == kinds


@settings(max_examples=40, deadline=None)
@given(st.lists(step, min_size=1, max_size=14), st.data())
def test_snapshot_plus_tail_equals_full_replay_and_prefixes_are_stable(
    steps: list[dict[str, Any]], data: st.DataObject
) -> None:
    log, live = live_run(steps)
    cut = data.draw(st.integers(min_value=0, max_value=len(log)))
    prefix_state = fold(SceneState(), log[:cut])
    snapshot = SceneState.from_dict(orjson.loads(orjson.dumps(prefix_state.to_dict())))
    assert fold(snapshot, log[cut:]).to_dict() == live.to_dict()
    # the state at a prefix never depends on what came after it
    assert fold(SceneState(), log[:cut]).to_dict() == prefix_state.to_dict()
    assert prefix_state.head_seq == cut - 1


def test_evolved_copies_fields_and_drops_the_cached_label() -> None:
    _log, live = live_run([{"mug_1": 0, "book_1": None, "detect": {"mug_1"}, "occlude": False}])
    track = next(iter(live.tracks.values()))
    assert track.label == "mug"
    relabeled = track.evolved(class_evidence={"cup": 3.0})
    assert relabeled.label == "cup" and track.label == "mug"
    assert relabeled.to_dict() == {**track.to_dict(), "class_evidence": {"cup": 3.0}}
    # Type checking refuses an unknown field; so does the copy at run time.
    with pytest.raises(TypeError, match="no changeable field"):
        track.evolved(colour="red")  # type: ignore[call-arg]
    with pytest.raises(TypeError, match="no changeable field"):
        track.evolved(track_id="trk-other")  # type: ignore[call-arg]
