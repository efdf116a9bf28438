"""Raw batch retention: when `pbdag gc` deleted a batch's raw body (batches.blob_collected_at).

Revision ID: 0005
Revises: 0004
Create Date: 2026-11-30
"""

import sqlalchemy as sa
from alembic import op

revision = "0005"
down_revision = "0004"
branch_labels = None
depends_on = None


def upgrade() -> None:
    with op.batch_alter_table("batches") as batch:
        batch.add_column(sa.Column("blob_collected_at", sa.Float))


def downgrade() -> None:
    with op.batch_alter_table("batches") as batch:
        batch.drop_column("blob_collected_at")
