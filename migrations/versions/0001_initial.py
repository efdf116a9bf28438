"""Initial schema: scenes, the event log, the batch queue, the track projection, snapshots.

Revision ID: 0001
Revises:
Create Date: 2026-11-21
"""

import sqlalchemy as sa
from alembic import op

revision = "0001"
down_revision = None
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.create_table(
        "scenes",
        sa.Column("id", sa.String(64), primary_key=True),
        sa.Column("name", sa.String(200), nullable=False),
        sa.Column("params", sa.Text, nullable=False),
        sa.Column("head_seq", sa.BigInteger, nullable=False),
        sa.Column("created_at", sa.Float, nullable=False),
    )
    op.create_table(
        "events",
        sa.Column("scene_id", sa.String(64), sa.ForeignKey("scenes.id"), primary_key=True),
        sa.Column("seq", sa.BigInteger, primary_key=True, autoincrement=False),
        sa.Column("type", sa.String(32), nullable=False),
        sa.Column("track_id", sa.String(64)),
        sa.Column("state", sa.String(32)),
        sa.Column("batch_id", sa.String(200)),
        sa.Column("frame_id", sa.String(200)),
        sa.Column("recorded_at", sa.Float, nullable=False),
        sa.Column("details", sa.Text, nullable=False),
    )
    op.create_index("ix_events_scene_track_seq", "events", ["scene_id", "track_id", "seq"])
    op.create_table(
        "batches",
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
        sa.Column("status", sa.String(16), nullable=False),
        sa.Column("attempts", sa.Integer, nullable=False, server_default="0"),
        sa.Column("lease_owner", sa.String(128)),
        sa.Column("lease_until", sa.Float),
        sa.Column("error", sa.Text),
        sa.Column("first_seq", sa.BigInteger),
        sa.Column("last_seq", sa.BigInteger),
        sa.Column("received_at", sa.Float, nullable=False),
        sa.Column("finished_at", sa.Float),
        sa.UniqueConstraint("scene_id", "batch_id", name="uq_batches_scene_batch"),
    )
    op.create_index("ix_batches_status_id", "batches", ["status", "id"])
    op.create_index("ix_batches_scene_status", "batches", ["scene_id", "status", "id"])
    op.create_table(
        "tracks",
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
        sa.Column("belief", sa.Text, nullable=False),
        sa.Column("updated_seq", sa.BigInteger, nullable=False),
    )
    op.create_index("ix_tracks_scene_label", "tracks", ["scene_id", "label"])
    op.create_index("ix_tracks_scene_state", "tracks", ["scene_id", "state"])
    op.create_index("ix_tracks_scene_parent", "tracks", ["scene_id", "parent"])
    op.create_table(
        "snapshots",
        sa.Column("scene_id", sa.String(64), sa.ForeignKey("scenes.id"), primary_key=True),
        sa.Column("seq", sa.BigInteger, primary_key=True, autoincrement=False),
        sa.Column("format_version", sa.Integer, nullable=False),
        sa.Column("body", sa.LargeBinary, nullable=False),
    )


def downgrade() -> None:
    for table in ("snapshots", "tracks", "batches", "events", "scenes"):
        op.drop_table(table)
