"""Retention: old revisions are thinned, and every revision kept reads exactly as it did before."""

from __future__ import annotations

import datetime as dt
from collections.abc import Iterator
from typing import Any

import numpy as np
import pytest
import sqlalchemy as sa

from shared.store import (
    Feature,
    GridLayer,
    MapStore,
    RetentionPolicy,
    RevisionWrite,
    StoreError,
    TopologyEdge,
    TopologyNode,
    WmsBin,
    schema,
)
from shared.store.retention import RevisionAge, revisions_to_keep

NOW = dt.datetime(2026, 11, 20, 12, 0, tzinfo=dt.UTC)
POLICY = RetentionPolicy(keep_all_s=2 * 3600, hourly_s=24 * 3600, keep_stages=frozenset({"operator", "wms"}))


def _age(revision_id: int, hours_ago: float, stage: str = "occupancy", *, pinned: bool = False) -> RevisionAge:
    return RevisionAge(revision_id, stage, NOW - dt.timedelta(hours=hours_ago), pinned)


def test_recent_revisions_are_all_kept_and_older_ones_thinned_per_hour_then_per_day() -> None:
    recent = [_age(100 + i, 0.01 * i) for i in range(1, 50)]  # the last half hour
    hourly = [_age(i, 10 - i / 10) for i in range(1, 31)]  # 3 hours, some 7 to 10 hours ago
    daily = [_age(50 + i, 74 - i / 5) for i in range(1, 11)]  # two hours, three days ago
    keep = revisions_to_keep([*hourly, *daily, *recent], POLICY, now=NOW)
    assert {r.id for r in recent} <= keep
    kept_hourly = {r.id for r in hourly} & keep
    hours = {r.created_at.replace(minute=0, second=0, microsecond=0) for r in hourly}
    assert len(kept_hourly) == len(hours)  # the newest of each hour
    assert {r.id for r in daily} & keep == {60}  # one a day: the newest of that day
    assert max(keep) == 149


def test_pinned_protected_and_each_stages_newest_revisions_are_never_thinned() -> None:
    old = [_age(1, 100, "wms"), _age(2, 100, "operator"), _age(3, 100, pinned=True), _age(4, 100, "pillars"),
           _age(5, 100), _age(6, 100), _age(7, 0.1)]
    assert revisions_to_keep(old, POLICY, now=NOW) == {1, 2, 3, 4, 6, 7}


def test_a_policy_with_a_negative_or_infinite_window_is_refused() -> None:
    with pytest.raises(StoreError, match="keep_all_s"):
        RetentionPolicy(keep_all_s=-1, hourly_s=0)
    with pytest.raises(StoreError, match="hourly_s"):
        RetentionPolicy(keep_all_s=0, hourly_s=float("inf"))


@pytest.fixture
def history_store(migrated_store_url: str) -> Iterator[MapStore]:
    map_store = MapStore(migrated_store_url, layer_history=1000)
    yield map_store
    map_store.close()


def _bin(key: str, x: float) -> Feature:
    return Feature("bin", key, {"type": "Point", "coordinates": [x, 1.0]}, {"level": 1}, 0.8)


def _write_history(store: MapStore, map_id: int) -> list[int]:
    """Forty revisions over forty hours from three mapping stages, an operator and the WMS; ids oldest first."""
    rng = np.random.default_rng(7)
    ids = []
    for step in range(40):
        if step % 3 == 0:
            grid = GridLayer("occupancy", rng.integers(-1, 100, (30, 40)).astype(np.int8), 0.05, 0.0, 0.0,
                             {"step": step})
            write = RevisionWrite("occupancy_mapping", layers=[grid])
        elif step % 3 == 1:  # bins come, move and go
            bins = [_bin(f"01-{k:03d}", k + 0.1 * (step % 5)) for k in range(step % 7, step % 7 + 4)]
            write = RevisionWrite("pillar_mapping", features={"bin": bins})
        else:
            nodes = [TopologyNode(f"r{k}", "room", float(k), float(step)) for k in range(step % 4 + 1)]
            edges = [TopologyEdge("r0", f"r{k}") for k in range(1, step % 4 + 1)]
            write = RevisionWrite("grid_decomposition", topology=(nodes, edges))
        if step == 17:
            ids.append(store.write_revision(map_id, RevisionWrite("operator", features={"dock": [
                Feature("dock", "D1", {"type": "Point", "coordinates": [0.0, float(step)]})]})).id)
        if step == 23:
            ids.append(store.replace_wms_bins(map_id, [WmsBin("A-1", 1.0, 2.0), WmsBin(f"A-{step}")]).id)
        ids.append(store.write_revision(map_id, write).id)
    with store.engine.begin() as connection:  # spread the revisions over the last forty hours
        for age_h, revision_id in enumerate(reversed(ids)):
            connection.execute(schema.revisions.update().where(schema.revisions.c.id == revision_id)
                               .values(created_at=NOW - dt.timedelta(hours=age_h, minutes=30)))
    return ids


def _read(store: MapStore, map_id: int, revision: int) -> dict[str, Any]:
    """Everything a client reads of the map at ``revision``; feature versions without the id of their row."""
    layer = store.layer(map_id, "occupancy", revision=revision)
    features = sorted((s.stage, s.feature.kind, s.feature.key, repr(s.feature.geometry),
                       repr(s.feature.properties), s.feature.confidence)
                      for s in store.features(map_id, revision=revision))
    nodes, edges = store.topology(map_id, revision=revision)
    return {
        "layer": None if layer is None else (layer.layer.data.tobytes(), layer.layer.data.dtype.str,
                                             layer.layer.data.shape, dict(layer.layer.meta)),
        "features": features,
        "topology": (nodes, edges),
        "wms": store.wms_bins(map_id, revision=revision),
    }


def _row_counts(store: MapStore) -> dict[str, int]:
    tables = (schema.revisions, schema.layers, schema.features, schema.topology_nodes, schema.topology_edges,
              schema.wms_bins)
    with store.engine.connect() as connection:
        return {t.name: connection.execute(sa.select(sa.func.count()).select_from(t)).scalar_one() for t in tables}


def test_compaction_thins_old_revisions_and_kept_ones_read_exactly_as_before(history_store: MapStore) -> None:
    site = history_store.ensure_map("site")
    ids = _write_history(history_store, site.id)
    pinned = ids[5]
    assert history_store.pin_revision(site.id, pinned) is not None
    before = {revision_id: _read(history_store, site.id, revision_id) for revision_id in ids}
    counts = _row_counts(history_store)
    policy = RetentionPolicy(keep_all_s=6 * 3600, hourly_s=0, keep_stages=frozenset({"operator", "wms"}))

    dry = history_store.compact(site.id, policy, now=NOW, dry_run=True)
    assert _row_counts(history_store) == counts  # a dry run changes nothing
    assert sum(dry.dropped_by_stage.values()) > 0 and "would drop" in dry.describe()

    done = history_store.compact(site.id, policy, now=NOW)
    assert (done.dropped_by_stage, done.rows_deleted) == (dry.dropped_by_stage, dry.rows_deleted)
    after = {r.id for r in history_store.revisions(site.id, limit=1000)}
    assert len(after) == done.revisions_kept < len(ids)
    assert pinned in after and ids[-6:] == sorted(after)[-6:]  # pinned and the last six hours stay
    stages = {r.stage for r in history_store.revisions(site.id, limit=1000)}
    assert {"operator", "wms", "occupancy_mapping", "pillar_mapping", "grid_decomposition"} <= stages
    for revision_id in sorted(after):
        assert _read(history_store, site.id, revision_id) == before[revision_id], revision_id
    shrunk = _row_counts(history_store)
    assert shrunk["revisions"] == len(after)
    assert sum(shrunk.values()) < sum(counts.values()) - len(ids) + len(after)  # rows no kept revision shows went

    again = history_store.compact(site.id, policy, now=NOW)
    assert sum(again.dropped_by_stage.values()) == 0  # nothing more to thin
    assert history_store.vacuum() == history_store.url.startswith("sqlite")


def test_the_store_keeps_working_after_compaction(history_store: MapStore) -> None:
    site = history_store.ensure_map("site")
    _write_history(history_store, site.id)
    history_store.compact(site.id, RetentionPolicy(keep_all_s=0, hourly_s=0), now=NOW)
    live_before = _read(history_store, site.id, history_store.latest_revision(site.id).id)  # type: ignore[union-attr]
    written = history_store.write_revision(site.id, RevisionWrite("pillar_mapping", features={
        "bin": [_bin("09-001", 9.0)]}))
    assert [s.feature.key for s in history_store.features(site.id, kinds=["bin"])] == ["09-001"]
    assert written.summary["features"]["bin"]["removed"] == len([
        f for f in live_before["features"] if f[:2] == ("pillar_mapping", "bin")])


def _migrate(store: MapStore, target: str, *, down: bool = False) -> None:
    from alembic import command
    from alembic.config import Config

    from shared.store.store import MIGRATIONS_DIR

    config = Config()
    config.set_main_option("script_location", str(MIGRATIONS_DIR))
    with store.engine.begin() as connection:
        config.attributes["connection"] = connection
        (command.downgrade if down else command.upgrade)(config, target)


def test_adding_pins_to_a_populated_store_loses_no_row_and_undoes_cleanly(store_url: str) -> None:
    store = MapStore(store_url, layer_history=1000)
    try:
        _migrate(store, "0004")
        site = store.ensure_map("site")
        _write_history(store, site.id)  # writes name no pin column, so they work on the 0004 schema too
        counts = _row_counts(store)
        _migrate(store, "head")
        assert _row_counts(store) == counts
        assert not any(r.pinned for r in store.revisions(site.id, limit=1000))
        _migrate(store, "0004", down=True)
        assert _row_counts(store) == counts
    finally:
        store.close()


def test_pinning_an_unknown_revision_says_so(history_store: MapStore) -> None:
    site = history_store.ensure_map("site")
    assert history_store.pin_revision(site.id, 12345) is None
    revision = history_store.write_revision(site.id, RevisionWrite("occupancy_mapping"))
    pinned = history_store.pin_revision(site.id, revision.id)
    assert pinned is not None and pinned.pinned
    unpinned = history_store.pin_revision(site.id, revision.id, pinned=False)
    assert unpinned is not None and not unpinned.pinned
