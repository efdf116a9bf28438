"""Logs written by older code replay to the same states, and their payloads to the same bytes.

Two golden logs: one written before events were typed (17 classes), one written before each
class had a topic of its own (all 22 classes, through the service).
"""

from __future__ import annotations

from typing import Any, get_args

import orjson
import pytest

from core.event_records import event_to_record
from core.events import BaselineLoaded, Event
from core.evolve import fold
from core.state import SceneState
from core.upcasters import baseline_fixture_v1, topic_of
from tests.golden_logs import (
    BEFORE_EVENT_TOPICS,
    BEFORE_TYPED_EVENTS,
    GoldenLog,
    decoded,
    laid_out_as,
    only_known_keys,
)

LOGS = [BEFORE_TYPED_EVENTS, BEFORE_EVENT_TOPICS]


def without_new_params(state: dict[str, Any], golden: dict[str, Any]) -> dict[str, Any]:
    """The state with only the parameter and track keys the golden state knew (later versions
    add some), and the snapshot format version set aside (it names a cache's layout)."""
    prune = only_known_keys
    fields = set(golden["tracks"][0]) if golden["tracks"] else set()
    return {
        **{key: value for key, value in state.items() if key in golden},
        "params": prune(state["params"], golden["params"]),
        "format_version": golden["format_version"],
        # Fields later versions derive from the same events (the visibility box) set aside.
        "tracks": [{k: v for k, v in t.items() if k in fields} for t in state["tracks"]],
    }


def stored_form(event: Event, stored_name: str) -> bytes:
    """The payload of `event` in the form a row stored under `stored_name` holds: today's, or,
    for a v1 `baseline_loaded`, the whole track record of each fixture."""
    details = event_to_record(event)["details"]
    if stored_name == "baseline_loaded":
        assert isinstance(event, BaselineLoaded)
        details = {**details, "fixtures": [baseline_fixture_v1(f) for f in details["fixtures"]]}
    return orjson.dumps(details)


@pytest.mark.parametrize("log", LOGS, ids=lambda log: log.name)
def test_every_stored_payload_reads_back_to_the_same_bytes(log: GoldenLog) -> None:
    rows = log.rows()
    assert len(rows) > 200
    for row in rows:
        event = decoded(row)
        record = event_to_record(event)
        assert stored_form(event, row["type"]).decode() == row["details"], (row["seq"], row["type"])
        envelope = (record["track_id"], record["state"], record["frame_id"])
        assert envelope == (row["track_id"], row["state"], row["frame_id"])
        # The class is the one its stored name (and, for `add` and `update`, its payload) names;
        # the audit type the API shows is the stored name of old.
        named = topic_of(row["type"], orjson.loads(row["details"]))
        assert record["topic"] == ("baseline_loaded_v2" if named == "baseline_loaded" else named)
        assert event.type == row["type"]


def test_the_logs_cover_every_event_class() -> None:
    def classes(log: GoldenLog) -> set[str]:
        return {type(decoded(row)).__name__ for row in log.rows()}

    everything = {cls.__name__ for cls in get_args(Event)}
    assert len(everything) == 23
    # Renaming a scene came after both logs were written.
    assert classes(BEFORE_EVENT_TOPICS) == everything - {"SceneRenamed"}
    assert classes(BEFORE_TYPED_EVENTS) == everything - {
        "SceneRenamed",
        "OccupancyEvidence",
        "InspectionTargeted",
        "BatchSkipped",
        "ObjectReidentified",
        "TrackRetired",
    }


@pytest.mark.parametrize("scene", [0, 1, 2, 3])
def test_replay_gives_the_state_the_code_before_typed_events_folded(scene: int) -> None:
    golden = BEFORE_TYPED_EVENTS.states()[str(scene)]
    rows = BEFORE_TYPED_EVENTS.scenes()[scene]
    state = fold(SceneState(), (decoded(row) for row in rows))
    assert without_new_params(state.to_dict(), golden) == golden
    # What later versions add to the state, as a log without occupancy or plans leaves it.
    assert state.occupancy.known_cells() == 0 and state.clock is None
    assert state.plan.lock is None and state.plan.locks == 0 and not state.plan.failed_views


@pytest.mark.parametrize("scene", [0, 1, 2, 3])
def test_replay_gives_the_state_json_the_code_before_topics_folded_byte_for_byte(
    scene: int,
) -> None:
    written = BEFORE_EVENT_TOPICS.states()[str(scene)]
    golden = orjson.dumps(written)  # the bytes as written
    rows = BEFORE_EVENT_TOPICS.scenes()[scene]
    state = fold(SceneState(), (decoded(row) for row in rows)).to_dict()
    assert orjson.dumps(laid_out_as(state, written)) == golden
