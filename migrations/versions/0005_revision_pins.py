"""revision pins

Revision ID: 0005
Revises: 0004
Create Date: 2026-11-25 23:40:00

A revision a client pinned (``aisle db pin``, ``PUT …/revisions/{id}/pin``) is never thinned by compaction.
Compaction deletes revisions; an index on each table's ``revision_id`` lets the database find (no) rows that
reference one without scanning the table.
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0005"
down_revision = "0004"
branch_labels = None
depends_on = None

VERSIONED_TABLES = ("layers", "features", "topology_nodes", "topology_edges", "wms_bins")


def upgrade() -> None:
    # A plain ADD COLUMN: batch mode would copy and drop the table on SQLite, and dropping it cascades to every
    # row of the map that references a revision.
    op.add_column("revisions", sa.Column("pinned", sa.Boolean(), nullable=False, server_default=sa.false()))
    for table in VERSIONED_TABLES:
        op.create_index(f"ix_{table}_revision_id", table, ["revision_id"])


def downgrade() -> None:
    for table in VERSIONED_TABLES:
        op.drop_index(f"ix_{table}_revision_id", table_name=table)
    op.drop_column("revisions", "pinned")  # SQLite >= 3.35
