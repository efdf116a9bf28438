"""The one SQLAlchemy MetaData of the service (Alembic's env.py imports it)."""

from __future__ import annotations

import sqlalchemy as sa

metadata = sa.MetaData()

scenes = sa.Table(
    "scenes",
    metadata,
    sa.Column("id", sa.String(64), primary_key=True),
    sa.Column("name", sa.String(200), nullable=False),
    sa.Column("params", sa.Text, nullable=False),  # canonical JSON, also in the seq-0 event
    sa.Column("head_seq", sa.BigInteger, nullable=False),
    sa.Column("created_at", sa.Float, nullable=False),  # unix seconds
    # Why the scene takes no more writes (an unreadable event; see `pbdag repair`), or NULL.
    sa.Column("quarantined", sa.Text),
)

# The append-only log: rows are inserted, never updated or deleted, except when an administrator
# deletes the whole scene (service/store/scene_deletion.py).
events = sa.Table(
    "events",
    metadata,
    sa.Column("scene_id", sa.String(64), sa.ForeignKey("scenes.id"), primary_key=True),
    sa.Column("seq", sa.BigInteger, primary_key=True, autoincrement=False),
    # The stored name: its class's topic (core/events.py), or an older name (core/upcasters.py).
    sa.Column("type", sa.String(32), nullable=False),
    sa.Column("track_id", sa.String(64)),
    sa.Column("state", sa.String(32)),
    sa.Column("batch_id", sa.String(200)),
    sa.Column("frame_id", sa.String(200)),
    sa.Column("recorded_at", sa.Float, nullable=False),
    sa.Column("details", sa.Text, nullable=False),  # orjson: exact float round trip
    # The robot's clock: the newest frame timestamp of the batch that appended the row (unix
    # seconds), for `as_of_time`. NULL on rows no batch appended (scene creation, commands)
    # and on rows stored before the column existed (migration 0007).
    sa.Column("batch_time", sa.Float),
)
sa.Index("ix_events_scene_track_seq", events.c.scene_id, events.c.track_id, events.c.seq)
sa.Index("ix_events_scene_batch_time", events.c.scene_id, events.c.batch_time, events.c.seq)

# The job queue: one row per accepted batch.
batches = sa.Table(
    "batches",
    metadata,
    sa.Column(
        "id",
        sa.BigInteger().with_variant(sa.Integer, "sqlite"),
        primary_key=True,
        autoincrement=True,
    ),
    sa.Column("scene_id", sa.String(64), sa.ForeignKey("scenes.id"), nullable=False),
    sa.Column("batch_id", sa.String(200), nullable=False),
    sa.Column("content_sha256", sa.String(64), nullable=False),
    sa.Column("blob_key", sa.String(128), nullable=False),
    sa.Column("frame_count", sa.Integer, nullable=False),
    sa.Column("status", sa.String(16), nullable=False),  # queued | running | done | dead
    sa.Column("attempts", sa.Integer, nullable=False, server_default="0"),
    sa.Column("lease_owner", sa.String(128)),
    sa.Column("lease_until", sa.Float),
    sa.Column("error", sa.Text),
    sa.Column("first_seq", sa.BigInteger),
    sa.Column("last_seq", sa.BigInteger),
    sa.Column("received_at", sa.Float, nullable=False),
    sa.Column("finished_at", sa.Float),
    sa.Column("not_before", sa.Float),  # a failed attempt's retry waits until then (backoff)
    sa.Column("blob_bytes", sa.BigInteger, nullable=False, server_default="0"),  # for quotas
    # When `pbdag gc` deleted the raw batch (retention); the row and its events stay.
    sa.Column("blob_collected_at", sa.Float),
    sa.UniqueConstraint("scene_id", "batch_id", name="uq_batches_scene_batch"),
)
sa.Index("ix_batches_status_id", batches.c.status, batches.c.id)
sa.Index("ix_batches_scene_status", batches.c.scene_id, batches.c.status, batches.c.id)

# Raw batches by content hash, when the blob backend is PostgreSQL (PBDAG_BLOB_BACKEND): a blob
# is inserted in the transaction that queues its batch. Opaque bytes; unused on SQLite.
blobs = sa.Table(
    "blobs",
    metadata,
    sa.Column("key", sa.String(64), primary_key=True),  # sha256 of content, hex
    sa.Column("content", sa.LargeBinary, nullable=False),
    sa.Column("size", sa.BigInteger, nullable=False),
    sa.Column("created_at", sa.Float, nullable=False),  # unix seconds
)

# Projection: the current track table, for SQL queries. Rebuilt from the log by `pbdag rebuild`.
tracks = sa.Table(
    "tracks",
    metadata,
    sa.Column("scene_id", sa.String(64), sa.ForeignKey("scenes.id"), primary_key=True),
    sa.Column("track_id", sa.String(64), primary_key=True),
    sa.Column("kind", sa.String(16), nullable=False),
    sa.Column("label", sa.String(200), nullable=False),
    sa.Column("state", sa.String(32), nullable=False),
    sa.Column("p_exist", sa.Float, nullable=False),
    sa.Column("center_x", sa.Float, nullable=False),
    sa.Column("center_y", sa.Float, nullable=False),
    sa.Column("center_z", sa.Float, nullable=False),
    sa.Column("parent", sa.String(64)),
    sa.Column("last_observed", sa.Float),
    sa.Column("belief", sa.Text, nullable=False),  # the full Track.to_dict()
    sa.Column("updated_seq", sa.BigInteger, nullable=False),
)
sa.Index("ix_tracks_scene_label", tracks.c.scene_id, tracks.c.label)
sa.Index("ix_tracks_scene_state", tracks.c.scene_id, tracks.c.state)
sa.Index("ix_tracks_scene_parent", tracks.c.scene_id, tracks.c.parent)

# Projection: state snapshots, a disposable cache for as_of (format version mismatch = replay).
snapshots = sa.Table(
    "snapshots",
    metadata,
    sa.Column("scene_id", sa.String(64), sa.ForeignKey("scenes.id"), primary_key=True),
    sa.Column("seq", sa.BigInteger, primary_key=True, autoincrement=False),
    sa.Column("format_version", sa.Integer, nullable=False),
    sa.Column("body", sa.LargeBinary, nullable=False),  # snapshot_codec.encode_snapshot
)

# Projection: frozen baseline packages, canonical JSON named by its sha256 (rebuilt bit for bit).
baselines = sa.Table(
    "baselines",
    metadata,
    sa.Column("scene_id", sa.String(64), sa.ForeignKey("scenes.id"), primary_key=True),
    sa.Column("version", sa.Integer, primary_key=True, autoincrement=False),
    sa.Column("seq", sa.BigInteger, nullable=False),
    sa.Column("sha256", sa.String(64), nullable=False),
    sa.Column("body", sa.LargeBinary, nullable=False),
)

# API bearer tokens (service/auth.py): only the sha256 of a token is kept, never the token.
api_tokens = sa.Table(
    "api_tokens",
    metadata,
    sa.Column("id", sa.String(32), primary_key=True),  # public, the `<id>` of pbdag_<id>_<secret>
    sa.Column("name", sa.String(200), nullable=False),
    sa.Column("scopes", sa.String(64), nullable=False),  # space-separated: read write admin
    sa.Column("token_sha256", sa.String(64), nullable=False),
    sa.Column("created_at", sa.Float, nullable=False),  # unix seconds
    sa.Column("revoked_at", sa.Float),
    sa.UniqueConstraint("token_sha256", name="uq_api_tokens_token_sha256"),
)

PROJECTION_TABLES = (tracks, snapshots, baselines)
