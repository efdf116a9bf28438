"""Rows stored in older forms, read as today's events (eventsourcing's upcasting).

The log is append-only: a row keeps the name and payload it was written with. Reading it, two
steps bring it to today's form (core/event_records.py applies them):

1. Its topic. Before each class had a topic of its own, six classes were stored under two
   names and told apart by their payload; `upcast_add` and `upcast_update` name them. Their
   payloads are today's.

   | stored name | payload                              | topic                 |
   |-------------|--------------------------------------|-----------------------|
   | `add`       | `kind` "object"                      | `object_added`        |
   | `add`       | `kind` "fixture"                     | `fixture_added`       |
   | `update`    | `evidence` "visible_miss"            | `visible_miss`        |
   | `update`    | `evidence` "reidentified"            | `object_reidentified` |
   | `update`    | `evidence` "observed", with `center` | `fixture_observed`    |
   | `update`    | `evidence` "observed", no `center`   | `object_observed`     |

   Every other stored name is the topic of one class.
2. Its payload. A topic whose payload changed form names the old form; `UPCASTERS` turns such
   a payload into the next version's, until the topic is a class's:
   `baseline_loaded` -> `baseline_loaded_v2` (`upcast_baseline_loaded_v1_v2`).

An upcaster refuses (ValueError) a payload it cannot carry over whole: reading a row never
loses what it says.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any

# The fields of a v1 `baseline_loaded` fixture that make its baseline record (the others hold
# what loading gives a fixture).
_V1_RECORD_FIELDS = ("track_id", "class_evidence", "existence_logodds", "center", "extent")


def upcast_add(details: Mapping[str, Any]) -> str:
    """The topic of a row stored under `add`."""
    return "fixture_added" if details.get("kind") == "fixture" else "object_added"


def upcast_update(details: Mapping[str, Any]) -> str:
    """The topic of a row stored under `update` (only a fixture's observation has a `center`)."""
    evidence = details.get("evidence")
    if evidence == "visible_miss":
        return "visible_miss"
    if evidence == "reidentified":
        return "object_reidentified"
    return "fixture_observed" if "center" in details else "object_observed"


# Old names shared by several classes -> the upcaster naming a row's class from its payload.
SHARED_NAMES: Mapping[str, Callable[[Mapping[str, Any]], str]] = {
    "add": upcast_add,
    "update": upcast_update,
}


def topic_of(stored_name: str, details: Mapping[str, Any]) -> str:
    """The topic of a row stored under `stored_name` (a shared old name, or a topic)."""
    upcaster = SHARED_NAMES.get(stored_name)
    return stored_name if upcaster is None else upcaster(details)


def baseline_fixture_v1(record: Mapping[str, Any]) -> dict[str, Any]:
    """A fixture as a v1 `baseline_loaded` stored it: the track record of the loaded fixture
    (confirmed, pinned, published at its center; every other field at its start value)."""
    center = record["center"]
    return {
        "track_id": record["track_id"],
        "kind": "fixture",
        "lifecycle": "confirmed",
        "class_evidence": record["class_evidence"],
        "existence_logodds": record["existence_logodds"],
        "center": center,
        "extent": record["extent"],
        "recent_centers": [],
        "parent_evidence": {},
        "parent": None,
        "embedding_sum": None,
        "embedding_count": 0,
        "last_observed": None,
        "last_observed_frame": None,
        "batches_observed": 0,
        "visible_misses": 0,
        "published_center": center,
        "pinned": True,
        "verification": None,
        "verdict_frame": None,
        "margin_sum": 0.0,
        "best_frame": None,
        "best_frame_support": 0,
        "inspection_status": None,
        "inspection_attempts": 0,
    }


def upcast_baseline_loaded_v1_v2(details: Mapping[str, Any]) -> tuple[str, dict[str, Any]]:
    """v1 stored each fixture as a whole track record; v2 stores its baseline record.

    Every other field of a v1 fixture must hold what loading gives it, or the row is refused.
    """
    fixtures = []
    for index, stored in enumerate(details["fixtures"]):
        record = {key: stored[key] for key in _V1_RECORD_FIELDS}
        extra = _v1_differences(stored, baseline_fixture_v1(record))
        if extra:
            raise ValueError(
                f"details.fixtures[{index}]: a v1 baseline_loaded fixture holding {extra} "
                "is not a loaded baseline fixture"
            )
        fixtures.append(record)
    return "baseline_loaded_v2", {**details, "fixtures": fixtures}


def _v1_differences(stored: Mapping[str, Any], loaded: Mapping[str, Any]) -> list[str]:
    """The fields of a stored v1 fixture that loading would not give it. A field an older v1
    lacks was read as its start value (all of them falsy); `box` and `capture_id` were stored
    only when set."""
    differing = []
    for key in sorted(stored.keys() | loaded.keys()):
        if key in ("box", "capture_id"):
            wrong = stored.get(key) is not None
        elif key not in loaded:
            wrong = True
        else:
            wrong = stored[key] != loaded[key] if key in stored else bool(loaded[key])
        if wrong:
            differing.append(key)
    return differing


# Old topic -> the upcaster of its payload to the next version's (topic, payload).
UPCASTERS: Mapping[str, Callable[[Mapping[str, Any]], tuple[str, dict[str, Any]]]] = {
    "baseline_loaded": upcast_baseline_loaded_v1_v2,
}
# Stored names that are no class's topic, by the audit type their rows have.
LEGACY_NAMES: Mapping[str, str] = {
    "add": "add",
    "update": "update",
    "baseline_loaded": "baseline_loaded",
}


def upcast(stored_name: str, details: Mapping[str, Any]) -> tuple[str, Mapping[str, Any]]:
    """A stored row's topic and payload in today's form."""
    topic = topic_of(stored_name, details)
    while topic in UPCASTERS:
        topic, details = UPCASTERS[topic](details)
    return topic, details
