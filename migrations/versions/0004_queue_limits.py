"""Retry backoff (batches.not_before), blob bytes per batch (quotas), quarantined scenes.

Revision ID: 0004
Revises: 0003
Create Date: 2026-11-30
"""

import sqlalchemy as sa
from alembic import op

revision = "0004"
down_revision = "0003"
branch_labels = None
depends_on = None


def upgrade() -> None:
    with op.batch_alter_table("batches") as batch:
        batch.add_column(sa.Column("not_before", sa.Float))
        batch.add_column(sa.Column("blob_bytes", sa.BigInteger, nullable=False, server_default="0"))
    with op.batch_alter_table("scenes") as batch:
        batch.add_column(sa.Column("quarantined", sa.Text))


def downgrade() -> None:
    with op.batch_alter_table("scenes") as batch:
        batch.drop_column("quarantined")
    with op.batch_alter_table("batches") as batch:
        batch.drop_column("blob_bytes")
        batch.drop_column("not_before")
