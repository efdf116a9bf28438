"""The deferred fallback: a carried object seen at its new place before its old place was seen
empty takes its identity back from the hypothesis it started, once its absence is established."""

from __future__ import annotations

import math

import numpy as np
import orjson

from core.event_records import event_from_record, event_to_record
from core.events import Event, ObjectReidentified, TrackRetired
from core.evolve import fold
from core.params import Params
from core.state import SceneState
from tests.core.carried_mugs import (
    SAME_AS_A,
    TURNED,
    C,
    carried,
)
from tests.core.scenes import track_events


def about(log: list[Event], track_id: str, batch: str) -> list[str]:
    return [e.type for e in track_events(log) if e.track_id == track_id and e.frame_id == batch]


def test_a_carried_mug_takes_its_identity_back_from_its_hypothesis_once_its_place_is_empty() -> (
    None
):
    state, log = carried(SAME_AS_A)
    # The first look at the empty place is one miss (one miss may be the detector's); the
    # second establishes the absence, and the hypothesis seen elsewhere is mug_1.
    assert about(log, "trk-000001", "e0-f0") == ["update"]
    assert about(log, "trk-000001", "e1-f0") == ["update", "move"]
    assert about(log, "trk-000003", "e1-f0") == ["retire"]
    update = next(e for e in log if isinstance(e, ObjectReidentified))
    assert (update.track_id, update.hypothesis, update.state) == (
        "trk-000001",
        "trk-000003",
        "confirmed",
    )
    assert update.appearance_cosine > 0.78
    retire = next(e for e in log if isinstance(e, TrackRetired))
    assert (retire.track_id, retire.reason, retire.merged_into) == (
        "trk-000003",
        "merged",
        "trk-000001",
    )
    # mug_2, in place all along, is untouched; mug_1 stands where it was seen, its misses at the
    # old place explained.
    mug_1, mug_2 = state.tracks["trk-000001"], state.tracks["trk-000002"]
    assert mug_2.lifecycle == "confirmed" and mug_2.visible_misses == 0
    assert math.dist(mug_2.center, (-0.3, 0.1, 1.95)) < 0.05
    assert mug_1.lifecycle == "confirmed" and mug_1.visible_misses == 0
    assert math.dist(mug_1.center, tuple(TURNED[:3, :3] @ np.array([0.0, 0.1, 1.95]))) < 0.05
    assert mug_1.published_center == mug_1.center
    assert state.tracks["trk-000003"].lifecycle == "retired"
    # The stored form replays to the same state.
    records = orjson.loads(orjson.dumps([event_to_record(e) for e in log]))
    replayed = fold(SceneState(), [event_from_record(r) for r in records])
    assert replayed.to_dict() == state.to_dict()


def test_a_different_mug_seen_elsewhere_never_takes_the_identity_of_a_missing_one() -> None:
    state, log = carried(C)  # another mug's appearance
    assert not any(isinstance(e, ObjectReidentified | TrackRetired) for e in log)
    assert state.tracks["trk-000003"].lifecycle == "tentative"


def test_the_deferred_fallback_is_off_with_the_fallback() -> None:
    params = Params.from_dict({"association": {"unique_class_fallback": False}})
    _, log = carried(SAME_AS_A, params)
    assert not any(isinstance(e, ObjectReidentified) for e in log)
