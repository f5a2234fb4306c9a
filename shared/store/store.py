"""The layered map store on SQLite (WAL) or PostgreSQL.

Every stage write is one revision in one transaction: its layers, features and topology land
together or not at all. Features and topology are versioned by revision (``revision_id`` made
them, ``retired_revision_id`` superseded them), so any revision of the map can be read back.
"""

from __future__ import annotations

import collections
import datetime as dt
import json
import logging
import os
import socket
import threading
import zlib
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
import sqlalchemy as sa
from sqlalchemy import event
from sqlalchemy.engine import Connection, Engine

from shared.store import schema
from shared.store.compaction import CompactionReport, compact_gap, gaps
from shared.store.records import (
    FEATURE_KINDS,
    Feature,
    GridLayer,
    MapInfo,
    Revision,
    RevisionWrite,
    StoredFeature,
    StoredLayer,
    StoreError,
    TopologyEdge,
    TopologyNode,
    WmsBin,
    WmsStock,
    WorkerInfo,
    bounds,
)
from shared.store.retention import RetentionPolicy, RevisionAge, revisions_to_keep

MIGRATIONS_DIR = Path(__file__).resolve().parents[2] / "migrations"

log = logging.getLogger(__name__)
_IDS_PER_STATEMENT = 5000
"""Row ids named in one ``IN (...)``, well below SQLite's and PostgreSQL's limits on bound parameters."""
_WMS_BATCH = 10_000
"""WMS bins written by one statement (an import of 200 000 is written in 20)."""


class FeatureRow(NamedTuple):
    """A feature row as stored: geometry and properties are the JSON text in the database."""

    id: int
    revision_id: int
    retired_revision_id: int | None
    """The revision that superseded the row; None while it is live."""
    stage: str
    kind: str
    key: str
    confidence: float | None
    bounds: tuple[float, float, float, float]
    """(min_x, min_y, max_x, max_y) of the geometry, metres."""
    geometry_json: str
    properties_json: str


class StoreUnavailableError(StoreError):
    """The database cannot be reached right now; the caller may retry later."""


def _check_unique(ids: Iterable[str], what: str) -> None:
    """:class:`StoreError` naming up to ten repeated ids (one pass: a WMS list holds 10^5 and more)."""
    repeated = sorted(i for i, n in collections.Counter(ids).items() if n > 1)
    if repeated:
        raise StoreError(f"{what} must be unique; repeated: {repeated[:10]}")


def _now() -> dt.datetime:
    return dt.datetime.now(dt.UTC)


def _aware(value: dt.datetime) -> dt.datetime:
    return value if value.tzinfo else value.replace(tzinfo=dt.UTC)


def _encode(data: np.ndarray[Any, Any]) -> bytes:
    return zlib.compress(np.ascontiguousarray(data).tobytes(), 1)


def _decode(blob: bytes, dtype: str, height: int, width: int) -> np.ndarray[Any, Any]:
    return np.frombuffer(zlib.decompress(blob), dtype=np.dtype(dtype)).reshape(height, width).copy()


def _same_json(stored: str, written: str) -> bool:
    """Whether JSON text read back from the database is the text ``json.dumps`` made of a value.

    SQLite and a PostgreSQL ``json`` column keep the text as written, so a plain comparison mostly decides; a
    database that normalises the text is compared by value.
    """
    return stored == written or json.loads(stored) == json.loads(written)


def _live_at(table: sa.Table, revision: int | None) -> sa.ColumnElement[bool]:
    if revision is None:
        return table.c.retired_revision_id.is_(None)
    return sa.and_(
        table.c.revision_id <= revision,
        sa.or_(table.c.retired_revision_id.is_(None), table.c.retired_revision_id > revision),
    )


def create_store_engine(url: str) -> Engine:
    """An engine for ``url``; SQLite gets WAL, a busy timeout and foreign keys."""
    if url.startswith("sqlite"):
        path = sa.make_url(url).database
        if path and path != ":memory:":
            Path(path).parent.mkdir(parents=True, exist_ok=True)
        engine = sa.create_engine(url, connect_args={"timeout": 30, "check_same_thread": False})

        @event.listens_for(engine, "connect")
        def _sqlite_pragmas(dbapi_connection: Any, _record: Any) -> None:
            cursor = dbapi_connection.cursor()
            cursor.execute("PRAGMA journal_mode=WAL")
            cursor.execute("PRAGMA synchronous=NORMAL")
            cursor.execute("PRAGMA foreign_keys=ON")
            cursor.close()

        return engine
    # An API process serves many requests at once, and each holds a connection only for its query.
    return sa.create_engine(url, pool_pre_ping=True, pool_size=20, max_overflow=30)


class MapStore:
    """Typed access to the layered map; build one per process and share it between threads."""

    def __init__(self, url: str, *, layer_history: int = 20) -> None:
        self.url = url
        self.engine = create_store_engine(url)
        self.layer_history = layer_history
        self._writes = threading.Condition()  # guards the two below
        self._writing = 0  # transactions under way
        self._writes_stopped = False

    def close(self) -> None:
        self.engine.dispose()

    def stop_writes(self) -> None:
        """Wait for the transactions under way to commit (or roll back) and refuse every later one with
        :class:`StoreUnavailableError`: a process that exits while its workers are still busy then leaves each
        revision stored whole or not at all, and no write starts as it goes."""
        with self._writes:
            self._writes_stopped = True
            self._writes.wait_for(lambda: self._writing == 0)

    # -- schema ---------------------------------------------------------------------------
    def upgrade(self) -> bool:
        """Bring the schema to the newest Alembic revision; whether there was anything to do.

        Alembic says nothing unless it migrates (then one line per migration), so commands that open the store
        (``aisle keys list``) print only their own output.
        """
        alembic_log = logging.getLogger("alembic")
        level = alembic_log.level
        alembic_log.setLevel(logging.WARNING)  # importing alembic logs its plugins, too
        try:
            from alembic import command
            from alembic.config import Config
            from alembic.runtime.migration import MigrationContext
            from alembic.script import ScriptDirectory

            config = Config()
            config.set_main_option("script_location", str(MIGRATIONS_DIR))
            heads = set(ScriptDirectory.from_config(config).get_heads())
            with self._begin() as connection:
                current = set(MigrationContext.configure(connection).get_current_heads())
                if current == heads:
                    return False
                log.info("migrating the map store schema from %s to %s", sorted(current) or "nothing", sorted(heads))
                logging.getLogger("alembic.runtime.migration").setLevel(logging.INFO)
                config.attributes["connection"] = connection
                command.upgrade(config, "head")
                return True
        finally:
            logging.getLogger("alembic.runtime.migration").setLevel(logging.NOTSET)
            alembic_log.setLevel(level)

    @contextmanager
    def _begin(self) -> Iterator[Connection]:
        with self._writes:
            if self._writes_stopped:
                raise StoreUnavailableError("the store takes no more writes: the process is stopping")
            self._writing += 1
        try:
            with self.engine.begin() as connection:
                yield connection
        except sa.exc.OperationalError as err:
            raise StoreUnavailableError(f"database unavailable: {err.orig}") from err
        except sa.exc.InterfaceError as err:
            raise StoreUnavailableError(f"database unavailable: {err.orig}") from err
        finally:
            with self._writes:
                self._writing -= 1
                self._writes.notify_all()

    @contextmanager
    def _read(self) -> Iterator[Connection]:
        try:
            with self.engine.connect() as connection:
                yield connection
        except (sa.exc.OperationalError, sa.exc.InterfaceError) as err:
            raise StoreUnavailableError(f"database unavailable: {err.orig}") from err
        except sa.exc.DataError as err:  # a value the database cannot compare, e.g. a NUL byte on PostgreSQL
            raise StoreError(f"the database refused a value of this query: {err.orig}") from err

    def ping(self) -> None:
        """Raise :class:`StoreUnavailableError` unless the database answers."""
        with self._read() as connection:
            connection.execute(sa.text("SELECT 1"))

    # -- maps and revisions ---------------------------------------------------------------
    def ensure_map(self, name: str, *, frame_id: str = "map") -> MapInfo:
        """The map called ``name``, created on first use."""
        found = self.get_map(name)
        if found is not None:
            return found
        try:
            with self._begin() as connection:
                connection.execute(schema.maps.insert().values(name=name, frame_id=frame_id, created_at=_now()))
        except sa.exc.IntegrityError:
            pass  # another process created it first
        created = self.get_map(name)
        assert created is not None
        return created

    def get_map(self, name_or_id: str | int) -> MapInfo | None:
        column = schema.maps.c.id if isinstance(name_or_id, int) else schema.maps.c.name
        with self._read() as connection:
            row = connection.execute(sa.select(schema.maps).where(column == name_or_id)).first()
        return None if row is None else MapInfo(row.id, row.name, row.frame_id, _aware(row.created_at))

    def maps(self) -> list[MapInfo]:
        with self._read() as connection:
            rows = connection.execute(sa.select(schema.maps).order_by(schema.maps.c.id)).all()
        return [MapInfo(r.id, r.name, r.frame_id, _aware(r.created_at)) for r in rows]

    def revisions(self, map_id: int, *, after_id: int = 0, limit: int = 100) -> list[Revision]:
        """Revisions of a map with id > ``after_id``, oldest first."""
        table = schema.revisions
        query = (sa.select(table).where(table.c.map_id == map_id, table.c.id > after_id)
                 .order_by(table.c.id).limit(limit))
        with self._read() as connection:
            return [self._revision(r) for r in connection.execute(query)]

    def latest_revision(self, map_id: int, *, stage: str | None = None, at_or_before: int | None = None
                        ) -> Revision | None:
        """The map's newest revision (of ``stage``, not after revision ``at_or_before``, if given), or None."""
        table = schema.revisions
        query = sa.select(table).where(table.c.map_id == map_id)
        if stage is not None:
            query = query.where(table.c.stage == stage)
        if at_or_before is not None:
            query = query.where(table.c.id <= at_or_before)
        query = query.order_by(table.c.id.desc()).limit(1)
        with self._read() as connection:
            row = connection.execute(query).first()
        return None if row is None else self._revision(row)

    @staticmethod
    def _revision(row: Any) -> Revision:
        return Revision(row.id, row.map_id, row.stage, _aware(row.created_at), row.input_start_ns,
                        row.input_end_ns, row.summary, bool(row.pinned))

    def pin_revision(self, map_id: int, revision_id: int, *, pinned: bool = True) -> Revision | None:
        """Pin revision ``revision_id`` of the map (or unpin it): compaction never thins a pinned revision.

        None if the map has no such revision (it may have been thinned already).
        """
        table = schema.revisions
        with self._begin() as connection:
            self._lock_map(connection, map_id)
            row = connection.execute(table.update().where(table.c.map_id == map_id, table.c.id == revision_id)
                                     .values(pinned=pinned).returning(*table.c)).first()
        return None if row is None else self._revision(row)

    # -- retention ------------------------------------------------------------------------
    def compact(self, map_id: int, policy: RetentionPolicy, *, now: dt.datetime | None = None,
                dry_run: bool = False) -> CompactionReport:
        """Thin the map's revisions by ``policy`` (as of ``now``, default: now); every kept revision still reads
        exactly as before. ``dry_run``: only count what would go.

        Thinned revisions are gone for good: reading the map at one is a 404 like any unknown revision.
        """
        table = schema.revisions
        map_info = self.get_map(map_id)
        if map_info is None:
            raise StoreError(f"no map with id {map_id}")
        with self._read() as connection:
            ages = [RevisionAge(r.id, r.stage, _aware(r.created_at), bool(r.pinned)) for r in connection.execute(
                sa.select(table.c.id, table.c.stage, table.c.created_at, table.c.pinned)
                .where(table.c.map_id == map_id).order_by(table.c.id))]
        keep = revisions_to_keep(ages, policy, now=now or _now())
        report = CompactionReport(map_info.name, dry_run, len(ages), len(keep))
        for a, b in gaps([r.id for r in ages], keep):
            with self._read() if dry_run else self._begin() as connection:
                compact_gap(connection, map_id, a, b, report)
        report.revisions_kept = report.revisions_before - sum(report.dropped_by_stage.values())
        return report

    def vacuum(self) -> bool:
        """Give the space of deleted rows back to the file system (SQLite ``VACUUM``); False on PostgreSQL, whose
        autovacuum reuses it. Needs the database to itself for a while."""
        if not self.url.startswith("sqlite"):
            return False
        with self.engine.connect().execution_options(isolation_level="AUTOCOMMIT") as connection:
            connection.execute(sa.text("VACUUM"))
            connection.execute(sa.text("PRAGMA wal_checkpoint(TRUNCATE)"))  # in WAL mode the file shrinks only now
        return True

    # -- writing --------------------------------------------------------------------------
    @staticmethod
    def _lock_map(connection: Connection, map_id: int) -> None:
        """Hold the map's row until the transaction ends, so the map's revisions commit in id order.

        Readers that follow a map by revision id (event streams resuming, the API's live index) then never see a
        revision before an older one. PostgreSQL locks the row; SQLite has one writer at a time anyway.
        """
        connection.execute(sa.select(schema.maps.c.id).where(schema.maps.c.id == map_id).with_for_update())

    def write_revision(self, map_id: int, write: RevisionWrite) -> Revision:
        """Store everything in ``write`` as one new revision, atomically.

        Features of a kind are replaced by ``write.features[kind]`` as a whole (for a kind in ``write.partial``,
        only those of the keys listed); a feature written exactly as it is stored (same key, geometry, properties
        and confidence) stays the row it is, with the revision that first wrote it, so a stage that rewrites all its
        features changes only the rows of those that changed.
        """
        with self._begin() as connection:
            self._lock_map(connection, map_id)
            created_at = _now()
            revision_id = connection.execute(
                schema.revisions.insert().values(
                    map_id=map_id, stage=write.stage, created_at=created_at, input_start_ns=write.input_start_ns,
                    input_end_ns=write.input_end_ns, summary={},
                ).returning(schema.revisions.c.id)
            ).scalar_one()
            summary: dict[str, Any] = dict(write.summary)
            summary["layers_updated"] = [layer.name for layer in write.layers]
            for layer in write.layers:
                self._insert_layer(connection, map_id, revision_id, layer)
            summary["features"] = {
                kind: self._replace_features(connection, map_id, revision_id, write.stage, kind, items,
                                             partial=kind in write.partial)
                for kind, items in write.features.items()
            }
            summary["topology_changed"] = write.topology is not None
            if write.topology is not None:
                self._replace_topology(connection, map_id, revision_id, write.stage, *write.topology)
            connection.execute(
                schema.revisions.update().where(schema.revisions.c.id == revision_id).values(summary=summary)
            )
        return Revision(revision_id, map_id, write.stage, created_at, write.input_start_ns, write.input_end_ns,
                        summary)

    def _insert_layer(self, connection: Connection, map_id: int, revision_id: int, layer: GridLayer) -> None:
        table = schema.layers
        connection.execute(table.insert().values(
            map_id=map_id, revision_id=revision_id, name=layer.name, dtype=layer.data.dtype.str,
            height=layer.data.shape[0], width=layer.data.shape[1], resolution_m=layer.resolution_m,
            origin_x_m=layer.origin_x_m, origin_y_m=layer.origin_y_m, data=_encode(layer.data),
            meta=dict(layer.meta),
        ))
        keep = (sa.select(table.c.id).where(table.c.map_id == map_id, table.c.name == layer.name)
                .order_by(table.c.revision_id.desc()).limit(self.layer_history))
        connection.execute(table.delete().where(
            table.c.map_id == map_id, table.c.name == layer.name, table.c.id.not_in(keep.scalar_subquery())
        ))

    @staticmethod
    def _replace_features(connection: Connection, map_id: int, revision_id: int, stage: str, kind: str,
                          items: Sequence[Feature], *, partial: bool = False) -> dict[str, int]:
        """Replace the stage's live features of ``kind`` by ``items`` (``partial``: only those of their keys)."""
        table = schema.features
        live = sa.and_(table.c.map_id == map_id, table.c.stage == stage, table.c.kind == kind,
                       table.c.retired_revision_id.is_(None))
        as_stored = sa.select(table.c.id, table.c.key, sa.cast(table.c.geometry, sa.Text).label("geometry"),
                              sa.cast(table.c.properties, sa.Text).label("properties"), table.c.confidence)
        if partial:
            keys = sorted({item.key for item in items})
            found = [row for start in range(0, len(keys), _IDS_PER_STATEMENT) for row in connection.execute(
                as_stored.where(live, table.c.key.in_(keys[start:start + _IDS_PER_STATEMENT])))]
            before = connection.execute(sa.select(sa.func.count()).select_from(table).where(live)).scalar_one()
        else:
            found, before = list(connection.execute(as_stored.where(live))), 0
        # key -> (row id, geometry text, properties text, confidence) of the live rows, as stored
        previous = {row.key: (row.id, row.geometry, row.properties, row.confidence) for row in found}
        kept: set[str] = set()
        rows = []
        moved = changed = 0
        for item in items:
            geometry, properties = json.dumps(dict(item.geometry)), json.dumps(dict(item.properties))
            stored = previous.get(item.key)
            if (stored is not None and item.key not in kept and _same_json(stored[1], geometry)
                    and _same_json(stored[2], properties) and stored[3] == item.confidence):
                kept.add(item.key)
                continue
            moved += stored is not None and not _same_json(stored[1], geometry)
            changed += stored is not None and _same_json(stored[1], geometry)
            min_x, min_y, max_x, max_y = bounds(item.geometry)
            rows.append({
                "map_id": map_id, "revision_id": revision_id, "stage": stage, "kind": kind, "key": item.key,
                "geometry": dict(item.geometry), "min_x": min_x, "min_y": min_y, "max_x": max_x, "max_y": max_y,
                "confidence": item.confidence, "properties": dict(item.properties),
            })
        retired = [row_id for key, (row_id, *_) in previous.items() if key not in kept]
        for start in range(0, len(retired), _IDS_PER_STATEMENT):
            connection.execute(table.update().where(table.c.id.in_(retired[start:start + _IDS_PER_STATEMENT]))
                               .values(retired_revision_id=revision_id))
        if rows:
            connection.execute(table.insert(), rows)
        listed = {item.key for item in items}
        added = len(listed - previous.keys())
        return {"added": added, "removed": len(previous.keys() - listed), "moved": moved, "changed": changed,
                "total": int(before) + added if partial else len(listed)}

    @staticmethod
    def _replace_topology(connection: Connection, map_id: int, revision_id: int, stage: str,
                          nodes: Sequence[TopologyNode], edges: Sequence[TopologyEdge]) -> None:
        for table in (schema.topology_nodes, schema.topology_edges):
            connection.execute(table.update().where(
                table.c.map_id == map_id, table.c.stage == stage, table.c.retired_revision_id.is_(None)
            ).values(retired_revision_id=revision_id))
        if nodes:
            connection.execute(schema.topology_nodes.insert(), [
                {"map_id": map_id, "revision_id": revision_id, "stage": stage, "key": n.key, "kind": n.kind,
                 "x_m": n.x_m, "y_m": n.y_m, "attributes": dict(n.attributes)} for n in nodes])
        if edges:
            connection.execute(schema.topology_edges.insert(), [
                {"map_id": map_id, "revision_id": revision_id, "stage": stage, "source": e.source,
                 "target": e.target, "attributes": dict(e.attributes)} for e in edges])

    # -- reading --------------------------------------------------------------------------
    def layer_names(self, map_id: int) -> list[str]:
        table = schema.layers
        with self._read() as connection:
            return list(connection.execute(
                sa.select(table.c.name).where(table.c.map_id == map_id).distinct().order_by(table.c.name)
            ).scalars())

    def layer_revision(self, map_id: int, name: str, *, revision: int | None = None) -> int | None:
        """The revision that wrote the newest version of layer ``name`` (at or before ``revision``), without
        reading its data; None if there is none."""
        table = schema.layers
        query = sa.select(sa.func.max(table.c.revision_id)).where(table.c.map_id == map_id, table.c.name == name)
        if revision is not None:
            query = query.where(table.c.revision_id <= revision)
        with self._read() as connection:
            found = connection.execute(query).scalar_one_or_none()
        return None if found is None else int(found)

    def layer(self, map_id: int, name: str, *, revision: int | None = None) -> StoredLayer | None:
        """The newest version of layer ``name`` (at or before ``revision`` if given)."""
        table = schema.layers
        query = sa.select(table).where(table.c.map_id == map_id, table.c.name == name)
        if revision is not None:
            query = query.where(table.c.revision_id <= revision)
        with self._read() as connection:
            row = connection.execute(query.order_by(table.c.revision_id.desc()).limit(1)).first()
        if row is None:
            return None
        data = _decode(row.data, row.dtype, row.height, row.width)
        layer = GridLayer(row.name, data, row.resolution_m, row.origin_x_m, row.origin_y_m, row.meta)
        return StoredLayer(row.revision_id, layer)

    def features(
        self,
        map_id: int,
        *,
        kinds: Sequence[str] | None = None,
        bbox: tuple[float, float, float, float] | None = None,
        revision: int | None = None,
        limit: int | None = None,
        offset: int = 0,
    ) -> list[StoredFeature]:
        """Features live at ``revision`` (default: now), optionally of ``kinds`` and touching ``bbox``."""
        table = schema.features
        query = sa.select(table).where(table.c.map_id == map_id, _live_at(table, revision))
        if kinds:
            query = query.where(table.c.kind.in_(list(kinds)))
        if bbox is not None:
            min_x, min_y, max_x, max_y = bbox
            query = query.where(table.c.max_x >= min_x, table.c.min_x <= max_x,
                                table.c.max_y >= min_y, table.c.min_y <= max_y)
        query = query.order_by(table.c.id).offset(offset)
        if limit is not None:
            query = query.limit(limit)
        with self._read() as connection:
            rows = connection.execute(query).all()
        return [StoredFeature(r.id, r.revision_id, r.stage,
                              Feature(r.kind, r.key, r.geometry, r.properties, r.confidence)) for r in rows]

    _FEATURE_ROW = (schema.features.c.id, schema.features.c.revision_id, schema.features.c.retired_revision_id,
                    schema.features.c.stage, schema.features.c.kind, schema.features.c.key,
                    schema.features.c.confidence, schema.features.c.min_x, schema.features.c.min_y,
                    schema.features.c.max_x, schema.features.c.max_y, sa.cast(schema.features.c.geometry, sa.Text),
                    sa.cast(schema.features.c.properties, sa.Text))

    @staticmethod
    def _feature_row(r: Any) -> FeatureRow:
        return FeatureRow(r[0], r[1], r[2], r[3], r[4], r[5], r[6], (r[7], r[8], r[9], r[10]), r[11], r[12])

    def live_feature_rows(self, map_id: int) -> list[FeatureRow]:
        """Every live feature of the map in id order, geometry and properties as the JSON text stored.

        For indexes that serve features as GeoJSON without decoding what they do not change.
        """
        table = schema.features
        query = (sa.select(*self._FEATURE_ROW)
                 # naming every kind lets the live index (map, kind, retired) find the live rows
                 .where(table.c.map_id == map_id, table.c.kind.in_(sorted(FEATURE_KINDS)),
                        table.c.retired_revision_id.is_(None))
                 .order_by(table.c.id))
        with self._read() as connection:
            return [self._feature_row(r) for r in connection.execute(query)]

    def feature_rows_changed(self, map_id: int, *, after: int, upto: int) -> list[FeatureRow]:
        """Feature rows that revisions ``after`` < r <= ``upto`` of the map wrote or retired, in id order.

        What turns the live features at revision ``after`` into those at ``upto``: drop the rows retired by
        then, add those written and still live then (``retired_revision_id`` is as stored now, so compare it
        with ``upto``). Revisions of a map commit in id order, so once ``upto`` is committed, so are they all.
        """
        table = schema.features
        written = sa.select(*self._FEATURE_ROW).where(table.c.map_id == map_id, table.c.revision_id > after,
                                                      table.c.revision_id <= upto)
        # Naming every kind lets the live index (map, kind, retired) find the rows retired meanwhile; "+ 0" keeps
        # SQLite (without statistics) from using the revision index for the written-before test instead.
        retired = sa.select(*self._FEATURE_ROW).where(
            table.c.map_id == map_id, table.c.kind.in_(sorted(FEATURE_KINDS)), table.c.retired_revision_id > after,
            table.c.retired_revision_id <= upto, table.c.revision_id + 0 <= after)
        with self._read() as connection:
            rows = [self._feature_row(r) for r in connection.execute(sa.union_all(written, retired))]
        return sorted(rows)

    def feature(self, map_id: int, kind: str, key: str, revision: int | None = None) -> StoredFeature | None:
        """The feature ``kind``/``key`` live at ``revision`` (default: now); the newest if several stages have it."""
        table = schema.features
        # The key index finds the few versions of one feature. The liveness test is written so no index can
        # serve it: given an indexable one, SQLite (without statistics) scans every live feature of the kind.
        retired = sa.func.coalesce(table.c.retired_revision_id, 0 if revision is None else revision + 1)
        live = retired == 0 if revision is None else sa.and_(table.c.revision_id <= revision, retired > revision)
        query = (sa.select(table).where(table.c.map_id == map_id, table.c.kind == kind, table.c.key == key, live)
                 .order_by(table.c.revision_id.desc(), table.c.id.desc()).limit(1))
        with self._read() as connection:
            r = connection.execute(query).first()
        if r is None:
            return None
        return StoredFeature(r.id, r.revision_id, r.stage, Feature(r.kind, r.key, r.geometry, r.properties,
                                                                    r.confidence))

    def topology(self, map_id: int, *, revision: int | None = None
                 ) -> tuple[list[TopologyNode], list[TopologyEdge]]:
        nodes_t, edges_t = schema.topology_nodes, schema.topology_edges
        with self._read() as connection:
            nodes = [TopologyNode(r.key, r.kind, r.x_m, r.y_m, r.attributes) for r in connection.execute(
                sa.select(nodes_t).where(nodes_t.c.map_id == map_id, _live_at(nodes_t, revision))
                .order_by(nodes_t.c.id))]
            edges = [TopologyEdge(r.source, r.target, r.attributes) for r in connection.execute(
                sa.select(edges_t).where(edges_t.c.map_id == map_id, _live_at(edges_t, revision))
                .order_by(edges_t.c.id))]
        return nodes, edges

    # -- the WMS's bin list ---------------------------------------------------------------
    def replace_wms_bins(self, map_id: int, items: Sequence[WmsBin], *, stage: str = "wms",
                         summary: Mapping[str, Any] | None = None,
                         before_commit: Callable[[int], None] | None = None) -> Revision:
        """Store ``items`` as the WMS's complete bin list, one new revision; the previous list is retired.

        ``summary`` is added to the revision's summary (e.g. the matching tolerance the import asked for).
        ``before_commit`` is called with the new revision's id once everything is written, before anyone can see
        the revision (while the map is locked), e.g. to prepare what readers of it will need.
        """
        _check_unique((item.wms_id for item in items), "WMS bin ids")
        table = schema.wms_bins
        with self._begin() as connection:
            self._lock_map(connection, map_id)
            created_at = _now()
            previous = connection.execute(sa.select(sa.func.count()).select_from(table).where(
                table.c.map_id == map_id, table.c.retired_revision_id.is_(None))).scalar_one()
            summary = {**(summary or {}), "layers_updated": [], "features": {}, "topology_changed": False,
                       "wms_bins": {"total": len(items), "previous": int(previous)}}
            revision_id = connection.execute(
                schema.revisions.insert().values(map_id=map_id, stage=stage, created_at=created_at, summary=summary)
                .returning(schema.revisions.c.id)
            ).scalar_one()
            connection.execute(table.update().where(table.c.map_id == map_id, table.c.retired_revision_id.is_(None))
                               .values(retired_revision_id=revision_id))
            # in batches, so no single call (building, sending or freeing the rows) holds the GIL for long
            for start in range(0, len(items), _WMS_BATCH):
                connection.execute(table.insert(), [
                    {"map_id": map_id, "revision_id": revision_id, "wms_id": item.wms_id, "x_m": item.x_m,
                     "y_m": item.y_m, "aisle": item.aisle, "bay": item.bay, "level": item.level,
                     "properties": dict(item.properties)} for item in items[start:start + _WMS_BATCH]])
            if before_commit is not None:
                before_commit(revision_id)
        return Revision(revision_id, map_id, stage, created_at, None, None, summary)

    def wms_bins(self, map_id: int, *, revision: int | None = None) -> list[WmsBin]:
        """The WMS bin list live at ``revision`` (default: now), in import order."""
        table = schema.wms_bins
        query = sa.select(table).where(table.c.map_id == map_id, _live_at(table, revision)).order_by(table.c.id)
        with self._read() as connection:
            return [WmsBin(r.wms_id, r.x_m, r.y_m, r.aisle, r.bay, r.level, r.properties)
                    for r in connection.execute(query)]

    # -- the WMS's stock list -------------------------------------------------------------
    def replace_wms_stock(self, map_id: int, items: Sequence[WmsStock], *, stage: str = "wms_stock",
                          summary: Mapping[str, Any] | None = None) -> Revision:
        """Store ``items`` as the WMS's complete stock list, one new revision; the previous list is retired.

        ``summary`` is added to the revision's summary (e.g. whether bins the list leaves out are empty).
        """
        _check_unique((item.bin_id for item in items), "WMS stock bin ids")
        table = schema.wms_stock
        with self._begin() as connection:
            self._lock_map(connection, map_id)
            created_at = _now()
            summary = {**(summary or {}), "layers_updated": [], "features": {}, "topology_changed": False,
                       "wms_stock": {"total": len(items), "holds_stock": sum(item.holds_stock for item in items)}}
            revision_id = connection.execute(
                schema.revisions.insert().values(map_id=map_id, stage=stage, created_at=created_at, summary=summary)
                .returning(schema.revisions.c.id)
            ).scalar_one()
            connection.execute(table.update().where(table.c.map_id == map_id, table.c.retired_revision_id.is_(None))
                               .values(retired_revision_id=revision_id))
            for start in range(0, len(items), _WMS_BATCH):
                connection.execute(table.insert(), [
                    {"map_id": map_id, "revision_id": revision_id, "bin_id": item.bin_id,
                     "holds_stock": item.holds_stock, "sku": item.sku, "quantity": item.quantity}
                    for item in items[start:start + _WMS_BATCH]])
        return Revision(revision_id, map_id, stage, created_at, None, None, summary)

    def wms_stock(self, map_id: int, *, revision: int | None = None) -> list[WmsStock]:
        """The WMS stock list live at ``revision`` (default: now), in import order."""
        table = schema.wms_stock
        query = sa.select(table).where(table.c.map_id == map_id, _live_at(table, revision)).order_by(table.c.id)
        with self._read() as connection:
            return [WmsStock(r.bin_id, bool(r.holds_stock), r.sku, r.quantity) for r in connection.execute(query)]

    # -- workers --------------------------------------------------------------------------
    def heartbeat(self, name: str, counters: dict[str, int], *, started_at: dt.datetime) -> None:
        """Record that worker ``name`` is running, with its counters."""
        table = schema.workers
        values = {"host": socket.gethostname(), "pid": os.getpid(), "started_at": started_at,
                  "heartbeat_at": _now(), "counters": counters}
        with self._begin() as connection:
            updated = connection.execute(table.update().where(table.c.name == name).values(**values)).rowcount
            if not updated:
                connection.execute(table.insert().values(name=name, **values))

    def workers(self) -> list[WorkerInfo]:
        with self._read() as connection:
            rows = connection.execute(sa.select(schema.workers).order_by(schema.workers.c.name)).all()
        return [WorkerInfo(r.name, r.host, r.pid, _aware(r.started_at), _aware(r.heartbeat_at), r.counters)
                for r in rows]

