"""wms stock

Revision ID: 0006
Revises: 0005
Create Date: 2026-11-26 03:00:00

The WMS's stock list (``PUT …/wms-stock``): per bin, whether the WMS says it holds stock, and what; versioned by
revision like the WMS bin list, so discrepancies against what the robots saw read as of any revision.
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0006"
down_revision = "0005"
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.create_table(
        "wms_stock",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("map_id", sa.Integer(), nullable=False),
        sa.Column("revision_id", sa.Integer(), nullable=False),
        sa.Column("retired_revision_id", sa.Integer(), nullable=True),
        sa.Column("bin_id", sa.String(length=128), nullable=False),
        sa.Column("holds_stock", sa.Boolean(), nullable=False),
        sa.Column("sku", sa.String(length=128), nullable=True),
        sa.Column("quantity", sa.Float(), nullable=True),
        sa.ForeignKeyConstraint(["map_id"], ["maps.id"], name=op.f("fk_wms_stock_map_id_maps"), ondelete="CASCADE"),
        sa.ForeignKeyConstraint(["revision_id"], ["revisions.id"], name=op.f("fk_wms_stock_revision_id_revisions"),
                                ondelete="CASCADE"),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_wms_stock")),
    )
    op.create_index("ix_wms_stock_live", "wms_stock", ["map_id", "retired_revision_id"])
    op.create_index("ix_wms_stock_revision_id", "wms_stock", ["revision_id"])


def downgrade() -> None:
    op.drop_index("ix_wms_stock_revision_id", table_name="wms_stock")
    op.drop_index("ix_wms_stock_live", table_name="wms_stock")
    op.drop_table("wms_stock")
