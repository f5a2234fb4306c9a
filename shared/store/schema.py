"""Tables of the layered map store (SQLAlchemy Core). Changed only through Alembic migrations."""

from __future__ import annotations

import sqlalchemy as sa

metadata = sa.MetaData(
    naming_convention={
        "ix": "ix_%(column_0_label)s",
        "uq": "uq_%(table_name)s_%(column_0_name)s",
        "fk": "fk_%(table_name)s_%(column_0_name)s_%(referred_table_name)s",
        "pk": "pk_%(table_name)s",
    }
)

maps = sa.Table(
    "maps",
    metadata,
    sa.Column("id", sa.Integer, primary_key=True),
    sa.Column("name", sa.String(64), nullable=False, unique=True),
    sa.Column("frame_id", sa.String(64), nullable=False),
    sa.Column("created_at", sa.DateTime(timezone=True), nullable=False),
)

revisions = sa.Table(
    "revisions",
    metadata,
    sa.Column("id", sa.Integer, primary_key=True),
    sa.Column("map_id", sa.Integer, sa.ForeignKey("maps.id", ondelete="CASCADE"), nullable=False, index=True),
    sa.Column("stage", sa.String(64), nullable=False),
    sa.Column("created_at", sa.DateTime(timezone=True), nullable=False),
    sa.Column("input_start_ns", sa.BigInteger, nullable=True),
    sa.Column("input_end_ns", sa.BigInteger, nullable=True),
    sa.Column("summary", sa.JSON, nullable=False),
    sa.Column("pinned", sa.Boolean, nullable=False, server_default=sa.false()),
)
"""``pinned``: a client asked to keep this revision; compaction never thins it."""

layers = sa.Table(
    "layers",
    metadata,
    sa.Column("id", sa.Integer, primary_key=True),
    sa.Column("map_id", sa.Integer, sa.ForeignKey("maps.id", ondelete="CASCADE"), nullable=False),
    sa.Column("revision_id", sa.Integer, sa.ForeignKey("revisions.id", ondelete="CASCADE"), nullable=False),
    sa.Column("name", sa.String(64), nullable=False),
    sa.Column("dtype", sa.String(16), nullable=False),
    sa.Column("width", sa.Integer, nullable=False),
    sa.Column("height", sa.Integer, nullable=False),
    sa.Column("resolution_m", sa.Float, nullable=False),
    sa.Column("origin_x_m", sa.Float, nullable=False),
    sa.Column("origin_y_m", sa.Float, nullable=False),
    sa.Column("data", sa.LargeBinary, nullable=False),
    sa.Column("meta", sa.JSON, nullable=False),
    sa.Index("ix_layers_map_name_revision", "map_id", "name", "revision_id"),
    sa.Index("ix_layers_revision_id", "revision_id"),
)

features = sa.Table(
    "features",
    metadata,
    sa.Column("id", sa.Integer, primary_key=True),
    sa.Column("map_id", sa.Integer, sa.ForeignKey("maps.id", ondelete="CASCADE"), nullable=False),
    sa.Column("revision_id", sa.Integer, sa.ForeignKey("revisions.id", ondelete="CASCADE"), nullable=False),
    sa.Column("retired_revision_id", sa.Integer, nullable=True),
    sa.Column("stage", sa.String(64), nullable=False),
    sa.Column("kind", sa.String(32), nullable=False),
    sa.Column("key", sa.String(128), nullable=False),
    sa.Column("geometry", sa.JSON, nullable=False),
    sa.Column("min_x", sa.Float, nullable=False),
    sa.Column("min_y", sa.Float, nullable=False),
    sa.Column("max_x", sa.Float, nullable=False),
    sa.Column("max_y", sa.Float, nullable=False),
    sa.Column("confidence", sa.Float, nullable=True),
    sa.Column("properties", sa.JSON, nullable=False),
    sa.Index("ix_features_live", "map_id", "kind", "retired_revision_id"),
    sa.Index("ix_features_key", "map_id", "kind", "key"),
    sa.Index("ix_features_bbox", "map_id", "min_x", "min_y"),
    sa.Index("ix_features_revision", "map_id", "revision_id"),
    sa.Index("ix_features_revision_id", "revision_id"),
)

topology_nodes = sa.Table(
    "topology_nodes",
    metadata,
    sa.Column("id", sa.Integer, primary_key=True),
    sa.Column("map_id", sa.Integer, sa.ForeignKey("maps.id", ondelete="CASCADE"), nullable=False),
    sa.Column("revision_id", sa.Integer, sa.ForeignKey("revisions.id", ondelete="CASCADE"), nullable=False),
    sa.Column("retired_revision_id", sa.Integer, nullable=True),
    sa.Column("stage", sa.String(64), nullable=False),
    sa.Column("key", sa.String(128), nullable=False),
    sa.Column("kind", sa.String(32), nullable=False),
    sa.Column("x_m", sa.Float, nullable=True),
    sa.Column("y_m", sa.Float, nullable=True),
    sa.Column("attributes", sa.JSON, nullable=False),
    sa.Index("ix_topology_nodes_live", "map_id", "retired_revision_id"),
    sa.Index("ix_topology_nodes_revision_id", "revision_id"),
)

topology_edges = sa.Table(
    "topology_edges",
    metadata,
    sa.Column("id", sa.Integer, primary_key=True),
    sa.Column("map_id", sa.Integer, sa.ForeignKey("maps.id", ondelete="CASCADE"), nullable=False),
    sa.Column("revision_id", sa.Integer, sa.ForeignKey("revisions.id", ondelete="CASCADE"), nullable=False),
    sa.Column("retired_revision_id", sa.Integer, nullable=True),
    sa.Column("stage", sa.String(64), nullable=False),
    sa.Column("source", sa.String(128), nullable=False),
    sa.Column("target", sa.String(128), nullable=False),
    sa.Column("attributes", sa.JSON, nullable=False),
    sa.Index("ix_topology_edges_live", "map_id", "retired_revision_id"),
    sa.Index("ix_topology_edges_revision_id", "revision_id"),
)

wms_bins = sa.Table(
    "wms_bins",
    metadata,
    sa.Column("id", sa.Integer, primary_key=True),
    sa.Column("map_id", sa.Integer, sa.ForeignKey("maps.id", ondelete="CASCADE"), nullable=False),
    sa.Column("revision_id", sa.Integer, sa.ForeignKey("revisions.id", ondelete="CASCADE"), nullable=False),
    sa.Column("retired_revision_id", sa.Integer, nullable=True),
    sa.Column("wms_id", sa.String(128), nullable=False),
    sa.Column("x_m", sa.Float, nullable=True),
    sa.Column("y_m", sa.Float, nullable=True),
    sa.Column("aisle", sa.Integer, nullable=True),
    sa.Column("bay", sa.Integer, nullable=True),
    sa.Column("level", sa.Integer, nullable=True),
    sa.Column("properties", sa.JSON, nullable=False),
    sa.Index("ix_wms_bins_live", "map_id", "retired_revision_id"),
    sa.Index("ix_wms_bins_id", "map_id", "wms_id"),
    sa.Index("ix_wms_bins_revision_id", "revision_id"),
)
"""The WMS's own bin list as last imported (versioned by revision like features); positions optional."""

wms_stock = sa.Table(
    "wms_stock",
    metadata,
    sa.Column("id", sa.Integer, primary_key=True),
    sa.Column("map_id", sa.Integer, sa.ForeignKey("maps.id", ondelete="CASCADE"), nullable=False),
    sa.Column("revision_id", sa.Integer, sa.ForeignKey("revisions.id", ondelete="CASCADE"), nullable=False),
    sa.Column("retired_revision_id", sa.Integer, nullable=True),
    sa.Column("bin_id", sa.String(128), nullable=False),
    sa.Column("holds_stock", sa.Boolean, nullable=False),
    sa.Column("sku", sa.String(128), nullable=True),
    sa.Column("quantity", sa.Float, nullable=True),
    sa.Index("ix_wms_stock_live", "map_id", "retired_revision_id"),
    sa.Index("ix_wms_stock_revision_id", "revision_id"),
)
"""The WMS's stock list as last imported: which bins it says hold stock (versioned by revision like features)."""

workers = sa.Table(
    "workers",
    metadata,
    sa.Column("name", sa.String(64), primary_key=True),
    sa.Column("host", sa.String(255), nullable=False),
    sa.Column("pid", sa.Integer, nullable=False),
    sa.Column("started_at", sa.DateTime(timezone=True), nullable=False),
    sa.Column("heartbeat_at", sa.DateTime(timezone=True), nullable=False),
    sa.Column("counters", sa.JSON, nullable=False),
)

api_keys = sa.Table(
    "api_keys",
    metadata,
    sa.Column("id", sa.Integer, primary_key=True),
    sa.Column("key_id", sa.String(16), nullable=False, unique=True),
    sa.Column("name", sa.String(64), nullable=False),
    sa.Column("role", sa.String(16), nullable=False),
    sa.Column("salt", sa.LargeBinary(32), nullable=False),
    sa.Column("secret_hash", sa.LargeBinary(64), nullable=False),
    sa.Column("created_at", sa.DateTime(timezone=True), nullable=False),
    sa.Column("revoked_at", sa.DateTime(timezone=True), nullable=True),
)
"""API keys: only a per-key salt and the scrypt hash of the secret; ``key_id`` is its public prefix."""
