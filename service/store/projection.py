"""The current track table (and the scene row's name) as SQL projections of the log, and
their rebuild."""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any

import orjson
import sqlalchemy as sa
from sqlalchemy.dialects import postgresql, sqlite

from core.baseline import baseline_package, canonical_bytes, package_sha256
from core.events import BaselineFrozen, Event
from core.evolve import fold
from core.state import SceneState, Track
from service.store.engine import read_transaction, write_transaction
from service.store.event_log import EventLog, StoredEvent
from service.store.snapshot_codec import SNAPSHOT_VERSION, encode_snapshot
from service.store.tables import baselines, scenes, snapshots, tracks


def track_row(scene_id: str, track: Track, seq: int) -> dict[str, Any]:
    """The projection row of one track."""
    return {
        "scene_id": scene_id,
        "track_id": track.track_id,
        "kind": track.kind,
        "label": track.label,
        "state": track.lifecycle,
        "p_exist": track.p_exist,
        "center_x": track.center[0],
        "center_y": track.center[1],
        "center_z": track.center[2],
        "parent": track.parent,
        "last_observed": track.last_observed,
        "belief": orjson.dumps(track.to_dict()).decode(),
        "updated_seq": seq,
    }


def last_seq_by_track(first_seq: int, new_events: Iterable[Event]) -> dict[str, int]:
    """For each track touched by events numbered from `first_seq`, the seq of its last event."""
    touched: dict[str, int] = {}
    for offset, event in enumerate(new_events):
        for track_id in event.touched_tracks():
            touched[track_id] = first_seq + offset
    return touched


def _upsert_tracks(dialect: str) -> sa.Insert:
    """One row per track, replacing the row of a track already there (PostgreSQL and SQLite
    have the same `ON CONFLICT ... DO UPDATE`)."""
    insert = (postgresql.insert if dialect == "postgresql" else sqlite.insert)(tracks)
    kept = {"scene_id", "track_id"}
    return insert.on_conflict_do_update(
        index_elements=[tracks.c.scene_id, tracks.c.track_id],
        set_={c.name: insert.excluded[c.name] for c in tracks.columns if c.name not in kept},
    )


# Built once per dialect: a statement built anew for every append, and the delete's list of
# ids compiled anew for every length, cost a worker about 1 ms of CPU a batch.
_UPSERT_TRACKS = {name: _upsert_tracks(name) for name in ("postgresql", "sqlite")}


def write_tracks(
    connection: sa.Connection, scene_id: str, state: SceneState, touched: Mapping[str, int]
) -> None:
    """Upsert the rows of the touched tracks (inside the caller's transaction)."""
    if not touched:
        return
    rows = [track_row(scene_id, state.tracks[i], touched[i]) for i in sorted(touched)]
    connection.execute(_UPSERT_TRACKS[connection.dialect.name], rows)


def write_scene_name(connection: sa.Connection, scene_id: str, name: str) -> None:
    """The scene row's name, as the log's newest `scene_created` or `scene_renamed` says."""
    connection.execute(sa.update(scenes).where(scenes.c.id == scene_id).values(name=name))


def write_baseline(
    connection: sa.Connection,
    scene_id: str,
    state_before: SceneState,
    event: BaselineFrozen,
    seq: int,
) -> bytes:
    """Store the package a freeze event names, rebuilt from the state just before it."""
    package = baseline_package(state_before, scene_id, event.version, seq)
    body = canonical_bytes(package)
    if package_sha256(package) != event.sha256:
        raise ValueError(f"baseline {event.version} of {scene_id}: package differs from its event")
    connection.execute(
        baselines.insert().values(
            scene_id=scene_id, version=event.version, seq=seq, sha256=event.sha256, body=body
        )
    )
    return body


def query_tracks(
    engine: sa.Engine,
    scene_id: str,
    *,
    label: str | None = None,
    state: str | None = None,
    parent: str | None = None,
) -> list[tuple[int, Track]]:
    """(seq of its last event, track) of a scene's projection rows, by label, state or parent."""
    query = sa.select(tracks).where(tracks.c.scene_id == scene_id)
    if label is not None:
        query = query.where(tracks.c.label == label)
    if state is not None:
        query = query.where(tracks.c.state == state)
    if parent is not None:
        query = query.where(tracks.c.parent == parent)
    with read_transaction(engine) as connection:
        rows = connection.execute(query.order_by(tracks.c.track_id)).all()
    return [(row.updated_seq, Track.from_dict(orjson.loads(row.belief))) for row in rows]


@dataclass
class SceneRebuild:
    """What `rebuild` found for one scene."""

    scene_id: str
    events: int
    tracks_differ: list[str] = field(default_factory=list)
    snapshots_differ: list[int] = field(default_factory=list)
    baselines_differ: list[int] = field(default_factory=list)
    name_differs: bool = False  # the scene row's name was not the log's (rewritten)
    # Snapshots that were in an older body format (a cache `as_of` ignored): rewritten in the
    # current one, not a difference.
    snapshots_reencoded: int = 0
    # Tracks whose stored belief lacked only fields a later version derives from the same
    # events (`TRACK_FIELDS_ADDED`): rewritten with them, not a difference.
    tracks_reencoded: int = 0

    @property
    def identical(self) -> bool:
        """True when the rebuilt projections equal the old ones bit for bit."""
        return not (
            self.tracks_differ
            or self.snapshots_differ
            or self.baselines_differ
            or self.name_differs
        )


def _projections(
    connection: sa.Connection, scene_id: str
) -> tuple[
    dict[str, dict[str, Any]], dict[int, bytes], dict[int, int], dict[int, tuple[int, str, Any]]
]:
    """The scene's projections as they stand: track rows, snapshot bodies and their formats by
    seq, baseline (seq, sha256, body) by version."""
    old_tracks = {
        row.track_id: dict(row._mapping)
        for row in connection.execute(sa.select(tracks).where(tracks.c.scene_id == scene_id))
    }
    old_snapshots, old_formats = {}, {}
    for row in connection.execute(
        sa.select(snapshots.c.seq, snapshots.c.format_version, snapshots.c.body).where(
            snapshots.c.scene_id == scene_id
        )
    ):
        old_snapshots[row.seq] = row.body
        old_formats[row.seq] = row.format_version
    old_baselines = {
        row.version: (row.seq, row.sha256, row.body)
        for row in connection.execute(sa.select(baselines).where(baselines.c.scene_id == scene_id))
    }
    return old_tracks, old_snapshots, old_formats, old_baselines


@dataclass
class _Replay:
    """A replay from seq 0 that can be fed in parts, snapshotting at the seqs it is given."""

    state: SceneState = field(default_factory=SceneState)
    count: int = 0
    head: int = -1
    snapshots: dict[int, bytes] = field(default_factory=dict)
    touched: dict[str, int] = field(default_factory=dict)
    frozen: list[tuple[SceneState, BaselineFrozen, int]] = field(default_factory=list)

    def feed(self, stored: Iterable[StoredEvent], snapshot_seqs: Iterable[int]) -> None:
        pending = sorted(seq for seq in snapshot_seqs if seq > self.head)
        batch: list[Event] = []
        for row in stored:
            event = row.to_core()
            if isinstance(event, BaselineFrozen):  # its package is rebuilt from the state before
                self.state, batch = fold(self.state, batch), []
                self.frozen.append((self.state, event, row.seq))
            batch.append(event)
            self.count += 1
            self.head = row.seq
            for track_id in event.touched_tracks():
                self.touched[track_id] = row.seq
            while pending and pending[0] < row.seq:  # a snapshot at no event's seq: skipped
                pending.pop(0)
            if pending and row.seq == pending[0]:
                self.state, batch = fold(self.state, batch), []
                self.snapshots[pending.pop(0)] = encode_snapshot(self.state)
        self.state = fold(self.state, batch)


# Fields of a track's belief added since projections were first written, each derived from
# the events every log already holds (when the track was first observed: its `add`).
TRACK_FIELDS_ADDED = ("first_observed",)


def _as_written_before(new: dict[str, Any], old: Mapping[str, Any]) -> dict[str, Any]:
    """A rebuilt row without the added fields its old row's belief lacks."""
    written = orjson.loads(old["belief"])
    belief = orjson.loads(new["belief"])
    for name in TRACK_FIELDS_ADDED:
        if name not in written:
            belief.pop(name, None)
    return {**new, "belief": orjson.dumps(belief).decode()}


def rebuild_scene(log: EventLog, scene_id: str) -> SceneRebuild:
    """Drop the scene's projections and rebuild them from its log; report any difference.

    Safe beside running workers: the long replay runs outside any write transaction, then one
    write transaction locks the scene's row (an append updates it, so appends to this scene
    wait), folds whatever was appended meanwhile, reads the projections as they stand at that
    head, compares and rewrites them. The report compares like with like, at one head seq."""
    with read_transaction(log.engine) as connection:  # the snapshots' seqs up to one head seq
        head = log.scene(scene_id, connection).head_seq
        early_snapshots = set(
            connection.execute(
                sa.select(snapshots.c.seq).where(snapshots.c.scene_id == scene_id)
            ).scalars()
        )
    replay = _Replay()
    replay.feed(log.iter_events(scene_id, up_to=head), early_snapshots)
    with write_transaction(log.engine) as connection:
        # An append updates the scene's row: locked here, appends to this scene wait (SQLite's
        # write transaction already holds the whole database).
        stored_name = connection.execute(
            sa.select(scenes.c.name).where(scenes.c.id == scene_id).with_for_update()
        ).scalar_one()
        old_tracks, old_snapshots, old_formats, old_baselines = _projections(connection, scene_id)
        replay.feed(log.read(scene_id, after=replay.head, connection=connection), old_snapshots)
        state, count, touched = replay.state, replay.count, replay.touched
        new_snapshots = {
            seq: replay.snapshots[seq] for seq in old_snapshots if seq in replay.snapshots
        }
        connection.execute(sa.delete(tracks).where(tracks.c.scene_id == scene_id))
        connection.execute(sa.delete(snapshots).where(snapshots.c.scene_id == scene_id))
        connection.execute(sa.delete(baselines).where(baselines.c.scene_id == scene_id))
        write_tracks(connection, scene_id, state, touched)
        if state.name != stored_name:
            write_scene_name(connection, scene_id, state.name)
        new_baselines = {
            event.version: (
                seq,
                event.sha256,
                write_baseline(connection, scene_id, before, event, seq),
            )
            for before, event, seq in replay.frozen
        }
        for seq, body in sorted(new_snapshots.items()):
            connection.execute(
                snapshots.insert().values(
                    scene_id=scene_id, seq=seq, format_version=SNAPSHOT_VERSION, body=body
                )
            )
    report = SceneRebuild(scene_id, count, name_differs=state.name != stored_name)
    for track_id in sorted(set(old_tracks) | set(state.tracks)):
        new = (
            track_row(scene_id, state.tracks[track_id], touched[track_id])
            if track_id in state.tracks
            else None
        )
        old = old_tracks.get(track_id)
        if new == old:
            continue
        if new is not None and old is not None and _as_written_before(new, old) == old:
            report.tracks_reencoded += 1
        else:
            report.tracks_differ.append(track_id)
    report.baselines_differ = [
        version
        for version in sorted(set(old_baselines) | set(new_baselines))
        if old_baselines.get(version) != new_baselines.get(version)
    ]
    current = [seq for seq in sorted(old_snapshots) if old_formats[seq] == SNAPSHOT_VERSION]
    report.snapshots_reencoded = len(old_snapshots) - len(current)
    report.snapshots_differ = [
        seq for seq in current if new_snapshots.get(seq) != old_snapshots[seq]
    ]
    return report
