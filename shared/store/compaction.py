"""Thinning a map's revisions so that every kept revision still reads exactly as before.

Rows are versioned by revision: a row written by revision W and retired by T (None: live) shows at every
revision r with W <= r < T. Between two consecutive kept revisions a < b, the revisions a < r < b go; a row
written there is then first seen at b, so its W becomes b (likewise its T), and a row both written and
retired within (a, b] showed at no kept revision and goes. A grid layer shows at r when it is the newest of
its name at or before r: of the versions written within (a, b], only the newest can show at b, so the others
go and that one is moved to b. Each gap is one transaction, so an interrupted compaction leaves a store that
reads as before at every revision it still has.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass, field

import sqlalchemy as sa
from sqlalchemy.engine import Connection

from shared.store import schema
from shared.store.records import FEATURE_KINDS

VERSIONED = (schema.features, schema.topology_nodes, schema.topology_edges, schema.wms_bins, schema.wms_stock)
"""Tables whose rows carry ``revision_id`` and ``retired_revision_id``."""


@dataclass(slots=True)
class CompactionReport:
    """What a compaction of one map removed (or, in a dry run, would remove)."""

    map_name: str
    dry_run: bool
    revisions_before: int
    revisions_kept: int
    dropped_by_stage: Counter[str] = field(default_factory=Counter)
    """Revisions thinned, by the stage that wrote them."""
    rows_deleted: Counter[str] = field(default_factory=Counter)
    """Rows no kept revision shows, by table."""
    gaps_skipped: int = 0
    """Runs of revisions left alone because one of them was pinned meanwhile."""

    def describe(self) -> str:
        """A few lines for people: what goes (or went) and what stays."""
        verb = "would drop" if self.dry_run else "dropped"
        dropped = sum(self.dropped_by_stage.values())
        stages = ", ".join(f"{stage} {n}" for stage, n in sorted(self.dropped_by_stage.items())) or "none"
        rows = ", ".join(f"{table} {n}" for table, n in sorted(self.rows_deleted.items()) if n) or "none"
        skipped = f"; {self.gaps_skipped} runs left alone (pinned meanwhile)" if self.gaps_skipped else ""
        return (f"map {self.map_name!r}: {verb} {dropped} of {self.revisions_before} revisions (by stage: {stages}), "
                f"keeping {self.revisions_kept}; rows no kept revision shows: {rows}{skipped}")


def gaps(ids: Sequence[int], keep: set[int]) -> list[tuple[int, int]]:
    """The (a, b) of consecutive kept revisions (a = 0 before the first) with thinned revisions between them.

    ``ids`` are every revision of the map in increasing order; the newest must be kept.
    """
    found: list[tuple[int, int]] = []
    previous, thinned = 0, False
    for revision_id in ids:
        if revision_id in keep:
            if thinned:
                found.append((previous, revision_id))
            previous, thinned = revision_id, False
        else:
            thinned = True
    if thinned:
        raise ValueError("the newest revision must be kept")
    return found


def _lock(connection: Connection, map_id: int) -> None:
    """Take the map for writing until the transaction ends (a write, so SQLite starts its write transaction now
    and PostgreSQL locks the row): stage writes and pins wait meanwhile."""
    maps = schema.maps
    connection.execute(maps.update().where(maps.c.id == map_id).values(frame_id=maps.c.frame_id))


def _dead_rows(table: sa.Table, map_id: int, a: int, b: int) -> sa.ColumnElement[bool]:
    """Rows written after ``a`` and retired by ``b``: no kept revision shows them."""
    where = sa.and_(table.c.map_id == map_id, table.c.revision_id > a,
                    table.c.retired_revision_id.is_not(None), table.c.retired_revision_id <= b)
    if table is schema.features:  # naming every kind lets the live index (map, kind, retired) serve the query
        where = sa.and_(where, table.c.kind.in_(sorted(FEATURE_KINDS)))
    return where


def _shadowed_layers(map_id: int, a: int, b: int) -> sa.ColumnElement[bool]:
    """Layer versions written within (a, b] with a newer one of their name there: none shows at a kept revision."""
    layers, newer = schema.layers, schema.layers.alias("newer")
    newest = (sa.select(sa.func.max(newer.c.revision_id))
              .where(newer.c.map_id == map_id, newer.c.name == layers.c.name,
                     newer.c.revision_id > a, newer.c.revision_id <= b)
              .scalar_subquery())
    return sa.and_(layers.c.map_id == map_id, layers.c.revision_id > a, layers.c.revision_id <= b,
                   layers.c.revision_id < newest)


def compact_gap(connection: Connection, map_id: int, a: int, b: int, report: CompactionReport) -> None:
    """Thin the revisions a < r < b of the map (a and b kept) in the transaction of ``connection``.

    Leaves them alone (counted in ``report.gaps_skipped``) if one was pinned after the plan was made.
    """
    revisions = schema.revisions
    between = sa.and_(revisions.c.map_id == map_id, revisions.c.id > a, revisions.c.id < b)
    if not report.dry_run:
        _lock(connection, map_id)
    if connection.execute(sa.select(sa.func.count()).where(between, revisions.c.pinned)).scalar_one():
        report.gaps_skipped += 1
        return
    report.dropped_by_stage.update({stage: count for stage, count in connection.execute(
        sa.select(revisions.c.stage, sa.func.count()).where(between).group_by(revisions.c.stage))})
    deletions = [(table, _dead_rows(table, map_id, a, b)) for table in VERSIONED]
    deletions.append((schema.layers, _shadowed_layers(map_id, a, b)))
    for table, where in deletions:
        if report.dry_run:
            report.rows_deleted[table.name] += connection.execute(
                sa.select(sa.func.count()).select_from(table).where(where)).scalar_one()
        else:
            report.rows_deleted[table.name] += connection.execute(table.delete().where(where)).rowcount
    if report.dry_run:
        return
    for table in (*VERSIONED, schema.layers):
        connection.execute(table.update().where(table.c.map_id == map_id, table.c.revision_id > a,
                                                table.c.revision_id < b).values(revision_id=b))
    for table in VERSIONED:
        connection.execute(table.update().where(table.c.map_id == map_id, table.c.retired_revision_id > a,
                                                table.c.retired_revision_id < b).values(retired_revision_id=b))
    connection.execute(revisions.delete().where(between))
