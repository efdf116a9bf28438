"""The robot's clock on the log: events.batch_time, the newest frame timestamp of the batch
that appended the row, indexed for `as_of_time`. Rows stored before stay NULL (append-only).

Revision ID: 0007
Revises: 0006
Create Date: 2026-12-03
"""

import sqlalchemy as sa
from alembic import op

revision = "0007"
down_revision = "0006"
branch_labels = None
depends_on = None


def upgrade() -> None:
    with op.batch_alter_table("events") as batch:
        batch.add_column(sa.Column("batch_time", sa.Float))
    op.create_index("ix_events_scene_batch_time", "events", ["scene_id", "batch_time", "seq"])


def downgrade() -> None:
    op.drop_index("ix_events_scene_batch_time", table_name="events")
    with op.batch_alter_table("events") as batch:
        batch.drop_column("batch_time")
