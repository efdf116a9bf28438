"""The golden logs under tests/resources: event rows stored by older code, and what it made of them."""

from __future__ import annotations

import base64
import gzip
import hashlib
from collections import defaultdict
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import orjson
import sqlalchemy as sa

from core.event_records import event_from_record
from core.events import Event
from service.store.tables import baselines, events, scenes, snapshots, tracks

RESOURCES = Path(__file__).resolve().parent / "resources"


@dataclass(frozen=True)
class GoldenLog:
    """One folder of tests/resources: `events.jsonl.gz` (rows as stored, `scene` numbering the
    scenes), `states.json.gz` (each scene's state as the old code folded it) and, when the log was
    dumped from a database, `tables.json.gz` (the other rows a rebuild reads)."""

    name: str

    @property
    def folder(self) -> Path:
        return RESOURCES / self.name

    def rows(self) -> list[dict[str, Any]]:
        """Every stored row, by scene then seq."""
        with gzip.open(self.folder / "events.jsonl.gz", "rb") as handle:
            return [orjson.loads(line) for line in handle]

    def scenes(self) -> dict[int, list[dict[str, Any]]]:
        """The rows of each scene, in seq order."""
        by_scene: dict[int, list[dict[str, Any]]] = defaultdict(list)
        for row in self.rows():
            by_scene[row["scene"]].append(row)
        return dict(by_scene)

    def states(self) -> dict[str, Any]:
        """Each scene's state JSON (by the scene's number as a string)."""
        states: dict[str, Any] = orjson.loads(gzip.decompress(self.read("states.json.gz")))
        return states

    def tables(self) -> dict[str, list[dict[str, Any]]]:
        """The rows of scenes, tracks, baselines and snapshots, bytes as base64."""
        tables: dict[str, list[dict[str, Any]]] = orjson.loads(
            gzip.decompress(self.read("tables.json.gz"))
        )
        return tables

    def read(self, name: str) -> bytes:
        return (self.folder / name).read_bytes()


BEFORE_TYPED_EVENTS = GoldenLog("log-before-typed-events")
BEFORE_EVENT_TOPICS = GoldenLog("log-before-event-topics")


def decoded(row: dict[str, Any]) -> Event:
    """A stored row as today's event."""
    return event_from_record({**row, "topic": row["type"], "details": orjson.loads(row["details"])})


def voxels_digested(state: dict[str, Any]) -> dict[str, Any]:
    """A state's JSON with its voxel map as the sha256 of its JSON (as the golden states keep it)."""
    voxels = orjson.dumps(state["voxels"])
    return {**state, "voxels": {"sha256": hashlib.sha256(voxels).hexdigest()}}


def only_known_keys(value: Any, like: Any) -> Any:
    """`value` with only the keys `like` has, at every level, in `like`'s order."""
    if isinstance(value, dict) and isinstance(like, dict):
        return {key: only_known_keys(value[key], like[key]) for key in like if key in value}
    return value


def laid_out_as(state: dict[str, Any], golden: dict[str, Any]) -> dict[str, Any]:
    """A state's JSON as the golden state lays it out: the voxel map digested, the parameters
    added since (switches whose defaults keep the old rules), the tracks' fields added since
    (their first observation time) and the format version (a cache's layout) set aside; every
    other byte as the state has it."""
    return {
        **voxels_digested(state),
        "format_version": golden["format_version"],
        "params": only_known_keys(state["params"], golden["params"]),
        "tracks": [
            {key: value for key, value in track.items() if key != "first_observed"}
            for track in state["tracks"]
        ],
    }


def insert_rows(connection: sa.Connection, log: GoldenLog) -> list[str]:
    """Every dumped row of `log` into a migrated, empty database; the scene ids by number."""
    tables = log.tables()

    def stored(table: sa.Table) -> list[dict[str, Any]]:
        binary = {c.name for c in table.columns if isinstance(c.type, sa.LargeBinary)}
        return [
            {key: base64.b64decode(value) if key in binary else value for key, value in row.items()}
            for row in tables[str(table.name)]
        ]

    rows = log.rows()
    connection.execute(scenes.insert(), stored(scenes))
    connection.execute(
        events.insert(), [{k: v for k, v in r.items() if k != "scene"} for r in rows]
    )
    for table in (tracks, baselines, snapshots):
        connection.execute(table.insert(), stored(table))
    numbered = {row["scene"]: row["scene_id"] for row in rows}
    return [numbered[number] for number in sorted(numbered)]
