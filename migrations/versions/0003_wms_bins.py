"""wms bins

Revision ID: 0003
Revises: 0002
Create Date: 2026-11-21 10:00:00
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0003"
down_revision = "0002"
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.create_table(
        "wms_bins",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("map_id", sa.Integer(), nullable=False),
        sa.Column("revision_id", sa.Integer(), nullable=False),
        sa.Column("retired_revision_id", sa.Integer(), nullable=True),
        sa.Column("wms_id", sa.String(length=128), nullable=False),
        sa.Column("x_m", sa.Float(), nullable=True),
        sa.Column("y_m", sa.Float(), nullable=True),
        sa.Column("aisle", sa.Integer(), nullable=True),
        sa.Column("bay", sa.Integer(), nullable=True),
        sa.Column("level", sa.Integer(), nullable=True),
        sa.Column("properties", sa.JSON(), nullable=False),
        sa.ForeignKeyConstraint(["map_id"], ["maps.id"], name=op.f("fk_wms_bins_map_id_maps"), ondelete="CASCADE"),
        sa.ForeignKeyConstraint(["revision_id"], ["revisions.id"], name=op.f("fk_wms_bins_revision_id_revisions"),
                                ondelete="CASCADE"),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_wms_bins")),
    )
    op.create_index("ix_wms_bins_live", "wms_bins", ["map_id", "retired_revision_id"])
    op.create_index("ix_wms_bins_id", "wms_bins", ["map_id", "wms_id"])


def downgrade() -> None:
    op.drop_index("ix_wms_bins_id", table_name="wms_bins")
    op.drop_index("ix_wms_bins_live", table_name="wms_bins")
    op.drop_table("wms_bins")
