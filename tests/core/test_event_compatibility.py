"""A log written before events were typed replays to the same states and the same bytes."""

from __future__ import annotations

import gzip
import json
from collections import defaultdict
from pathlib import Path
from typing import Any

import orjson
import pytest

from core.event_records import event_from_record, event_to_record
from core.events import Event
from core.evolve import fold
from core.state import SceneState

RESOURCES = Path(__file__).resolve().parents[1] / "resources" / "log-before-typed-events"


def stored_rows() -> dict[int, list[dict[str, Any]]]:
    """The golden rows per scene, in seq order."""
    scenes: dict[int, list[dict[str, Any]]] = defaultdict(list)
    with gzip.open(RESOURCES / "events.jsonl.gz", "rt") as handle:
        for line in handle:
            row = json.loads(line)
            scenes[row["scene"]].append(row)
    return dict(scenes)


def decoded(row: dict[str, Any]) -> Event:
    return event_from_record({**row, "details": orjson.loads(row["details"])})


def without_new_params(state: dict[str, Any], golden: dict[str, Any]) -> dict[str, Any]:
    """The state with only the parameter and track keys the golden state knew (later versions
    add some), and the snapshot format version set aside (it names a cache's layout)."""

    def prune(value: Any, like: Any) -> Any:
        if isinstance(value, dict) and isinstance(like, dict):
            return {key: prune(value[key], like[key]) for key in like if key in value}
        return value

    fields = set(golden["tracks"][0]) if golden["tracks"] else set()
    return {
        **{key: value for key, value in state.items() if key in golden},
        "params": prune(state["params"], golden["params"]),
        "format_version": golden["format_version"],
        # Fields later versions derive from the same events (the visibility box) set aside.
        "tracks": [{k: v for k, v in t.items() if k in fields} for t in state["tracks"]],
    }


def test_every_stored_event_serializes_back_to_the_same_bytes() -> None:
    rows = [row for scene in stored_rows().values() for row in scene]
    assert len(rows) > 200
    for row in rows:
        event = decoded(row)
        record = event_to_record(event)
        assert orjson.dumps(record["details"]).decode() == row["details"], (row["seq"], row["type"])
        assert (record["type"], record["track_id"], record["state"], record["frame_id"]) == (
            row["type"],
            row["track_id"],
            row["state"],
            row["frame_id"],
        )


def test_the_log_covers_every_event_class() -> None:
    classes = {type(decoded(row)).__name__ for scene in stored_rows().values() for row in scene}
    assert classes == {
        "SceneCreated",
        "FixtureEvidence",
        "ObjectAdded",
        "FixtureAdded",
        "ObjectObserved",
        "FixtureObserved",
        "VisibleMiss",
        "TrackConfirmed",
        "TrackMoved",
        "TrackReparented",
        "TrackDemoted",
        "TrackRemoved",
        "VerificationRequested",
        "TrackVerified",
        "BaselineFrozen",
        "BaselineLoaded",
        "InspectionRecorded",
    }


@pytest.mark.parametrize("scene", [0, 1, 2, 3])
def test_replay_gives_the_state_the_old_code_folded(scene: int) -> None:
    golden = orjson.loads(gzip.decompress((RESOURCES / "states.json.gz").read_bytes()))[str(scene)]
    state = fold(SceneState(), (decoded(row) for row in stored_rows()[scene]))
    assert without_new_params(state.to_dict(), golden) == golden
    # What later versions add to the state, as a log without occupancy or plans leaves it.
    assert state.occupancy.known_cells() == 0 and state.clock is None
    assert state.plan.lock is None and state.plan.locks == 0 and not state.plan.failed_views
