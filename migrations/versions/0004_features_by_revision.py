"""features by revision

Revision ID: 0004
Revises: 0003
Create Date: 2026-12-05 10:00:00

An index of feature rows by the revision that wrote them, so the API's live index can read just what the
revisions since its last look wrote (``MapStore.feature_rows_changed``) instead of every live feature.
"""

from __future__ import annotations

from alembic import op

revision = "0004"
down_revision = "0003"
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.create_index("ix_features_revision", "features", ["map_id", "revision_id"])


def downgrade() -> None:
    op.drop_index("ix_features_revision", table_name="features")
