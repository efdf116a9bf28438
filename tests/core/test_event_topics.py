"""One topic per event class, registered once (the `Event` union), and the upcasters of rows
stored under the older names."""

from __future__ import annotations

from dataclasses import fields
from typing import Any, get_args

import orjson
import pytest
import sqlalchemy as sa

from core.event_records import (
    EVENT_CLASSES,
    STORED_NAMES,
    event_class,
    event_from_record,
    event_to_record,
    stored_names,
)
from core.events import Event, VisibleMiss
from core.state import Track, TrackChanges
from core.upcasters import LEGACY_NAMES, UPCASTERS, baseline_fixture_v1, upcast
from service.store.tables import events
from tests.golden_logs import BEFORE_EVENT_TOPICS


def test_every_event_class_has_a_topic_of_its_own() -> None:
    classes = get_args(Event)
    assert all("topic" in cls.__dict__ for cls in classes)  # declared, never inherited
    assert len(EVENT_CLASSES) == len(classes) == 23
    assert set(EVENT_CLASSES.values()) == set(classes)
    # An old name is never a topic again: its rows would be read as the new class.
    assert set(EVENT_CLASSES).isdisjoint(LEGACY_NAMES)
    assert set(UPCASTERS) <= set(LEGACY_NAMES)
    column = events.c.type.type
    assert isinstance(column, sa.String) and column.length is not None
    assert max(map(len, [*EVENT_CLASSES, *LEGACY_NAMES])) <= column.length


def test_each_audit_type_names_every_topic_stored_under_it() -> None:
    assert STORED_NAMES["add"] == ("add", "fixture_added", "object_added")
    assert STORED_NAMES["update"] == (
        "fixture_observed",
        "object_observed",
        "object_reidentified",
        "update",
        "visible_miss",
    )
    assert STORED_NAMES["baseline_loaded"] == ("baseline_loaded", "baseline_loaded_v2")
    assert STORED_NAMES["confirm"] == ("confirm",)
    assert set(STORED_NAMES) == {cls.type for cls in get_args(Event)}


def test_a_row_under_its_topic_and_under_its_old_name_reads_as_one_class() -> None:
    miss = VisibleMiss(
        track_id="trk-000001",
        state="tentative",
        frame_id="f0",
        samples_passed=40,
        samples_total=50,
        existence_logodds=-0.5,
        p_exist=0.38,
        visible_misses=1,
    )
    record = orjson.loads(orjson.dumps(event_to_record(miss)))
    assert record["topic"] == "visible_miss" and miss.type == "update"
    assert event_from_record(record) == miss
    assert event_from_record({**record, "topic": "update"}) == miss
    assert stored_names("update", record["details"]) == ("visible_miss", "update")
    assert stored_names("visible_miss", record["details"]) == ("visible_miss", "update")


def test_an_unknown_stored_name_is_refused_by_name_and_shown_as_it_is() -> None:
    with pytest.raises(ValueError, match="unknown event type 'teleport'"):
        event_from_record({"topic": "teleport", "details": {}})
    with pytest.raises(ValueError, match="'add'"):
        event_class("add")  # an old name, no class's topic
    assert stored_names("teleport", {}) == ("teleport", "teleport")


def v1_loaded(**fixture_changes: Any) -> dict[str, Any]:
    """The golden log's v1 `baseline_loaded` payload, its first fixture changed."""
    row = next(r for r in BEFORE_EVENT_TOPICS.rows() if r["type"] == "baseline_loaded")
    details: dict[str, Any] = orjson.loads(row["details"])
    details["fixtures"][0] = {**details["fixtures"][0], **fixture_changes}
    return details


def test_a_v1_baseline_fixture_carries_over_whole_and_back() -> None:
    details = v1_loaded()
    topic, upcast_details = upcast("baseline_loaded", details)
    assert topic == "baseline_loaded_v2"
    assert [baseline_fixture_v1(f) for f in upcast_details["fixtures"]] == details["fixtures"]
    assert list(upcast_details["fixtures"][0]) == [
        "track_id",
        "class_evidence",
        "existence_logodds",
        "center",
        "extent",
    ]


def test_an_older_v1_fixture_without_fields_at_their_start_value_still_reads() -> None:
    details = v1_loaded()
    for key in ("inspection_attempts", "inspection_status", "margin_sum"):
        del details["fixtures"][0][key]
    _topic, upcast_details = upcast("baseline_loaded", details)
    assert upcast_details["fixtures"][0]["track_id"] == details["fixtures"][0]["track_id"]


@pytest.mark.parametrize(
    ("changes", "named"),
    [
        ({"pinned": False}, "pinned"),
        ({"published_center": [0.0, 0.0, 0.0]}, "published_center"),
        ({"box": [0.0, 0.0, 0.0, 1.0, 1.0, 1.0]}, "box"),
        ({"colour": "red"}, "colour"),
    ],
)
def test_a_v1_fixture_that_says_more_than_its_record_is_refused(
    changes: dict[str, Any], named: str
) -> None:
    with pytest.raises(ValueError, match=rf"details.fixtures\[0\].*'{named}'"):
        upcast("baseline_loaded", v1_loaded(**changes))


def test_a_track_change_names_any_field_but_the_identity_and_the_kind() -> None:
    assert TrackChanges.__optional_keys__ == {f.name for f in fields(Track)} - {"track_id", "kind"}
