"""The layered map store on SQLite and PostgreSQL: atomic revisions, history, live reads."""

from __future__ import annotations

import logging
import threading

import numpy as np
import pytest
import sqlalchemy as sa

from shared.store import (
    Feature,
    GridLayer,
    MapStore,
    RevisionWrite,
    StoreError,
    StoreUnavailableError,
    TopologyEdge,
    TopologyNode,
    WmsBin,
)
from tests.helpers import wait_for


def _bin(key: str, x: float, y: float) -> Feature:
    return Feature("bin", key, {"type": "Point", "coordinates": [x, y]}, {"aisle": key[:2]}, 0.9)


def _grid(value: int, shape: tuple[int, int] = (40, 60)) -> GridLayer:
    return GridLayer("occupancy", np.full(shape, value, np.int8), 0.05, -1.0, -2.0, {"source": "test"})


def test_layer_round_trips_with_geometry(store: MapStore) -> None:
    site = store.ensure_map("site")
    data = np.arange(40 * 60, dtype=np.int16).reshape(40, 60) % 101
    store.write_revision(site.id, RevisionWrite("occupancy_mapping", layers=[
        GridLayer("occupancy", data.astype(np.int8), 0.05, -1.0, -2.0)]))
    stored = store.layer(site.id, "occupancy")
    assert stored is not None
    np.testing.assert_array_equal(stored.layer.data, data.astype(np.int8))
    assert (stored.layer.resolution_m, stored.layer.origin_x_m, stored.layer.origin_y_m) == (0.05, -1.0, -2.0)


def test_old_layer_versions_are_pruned_but_readable_by_revision(store: MapStore) -> None:
    site = store.ensure_map("site")
    revisions = [store.write_revision(site.id, RevisionWrite("occ", layers=[_grid(v)])).id for v in range(5)]
    latest = store.layer(site.id, "occupancy")
    assert latest is not None and latest.revision_id == revisions[-1] and latest.layer.data[0, 0] == 4
    at_third = store.layer(site.id, "occupancy", revision=revisions[3])
    assert at_third is not None and at_third.layer.data[0, 0] == 3
    assert store.layer(site.id, "occupancy", revision=revisions[0]) is None  # history keeps 3 versions


def test_features_are_replaced_per_stage_and_kind_with_history(store: MapStore) -> None:
    site = store.ensure_map("site")
    first = store.write_revision(site.id, RevisionWrite("pillars", features={
        "bin": [_bin("01-01", 1, 1), _bin("01-02", 2, 1)]}))
    second = store.write_revision(site.id, RevisionWrite("pillars", features={
        "bin": [_bin("01-02", 2.5, 1), _bin("01-03", 3, 1)]}))
    assert second.summary["features"]["bin"] == {"added": 1, "removed": 1, "moved": 1, "changed": 0, "total": 2}
    assert sorted(f.feature.key for f in store.features(site.id, kinds=["bin"])) == ["01-02", "01-03"]
    assert sorted(f.feature.key for f in store.features(site.id, revision=first.id)) == ["01-01", "01-02"]
    inside = store.features(site.id, bbox=(2.2, 0.0, 2.8, 2.0))
    assert [f.feature.key for f in inside] == ["01-02"]


def test_a_feature_written_as_stored_keeps_its_row_and_history_stays_exact(store: MapStore) -> None:
    site = store.ensure_map("site")
    first = store.write_revision(site.id, RevisionWrite("pillars", features={
        "bin": [_bin("01-01", 1, 1), _bin("01-02", 2, 1)]}))
    second = store.write_revision(site.id, RevisionWrite("pillars", features={
        "bin": [_bin("01-01", 1, 1), _bin("01-02", 2.5, 1), _bin("01-03", 3, 1)]}))

    live = {f.feature.key: f for f in store.features(site.id, kinds=["bin"])}
    changed = store.feature_rows_changed(site.id, after=first.id, upto=second.id)

    assert live["01-01"].revision_id == first.id  # unchanged: the row first written
    assert live["01-02"].revision_id == live["01-03"].revision_id == second.id
    assert second.summary["features"]["bin"] == {"added": 1, "removed": 0, "moved": 1, "changed": 0, "total": 3}
    assert [(f.feature.key, f.feature.geometry["coordinates"]) for f in store.features(site.id, revision=first.id)
            ] == [("01-01", [1, 1]), ("01-02", [2, 1])]
    assert [(row.key, row.revision_id, row.retired_revision_id) for row in changed] == [
        ("01-02", first.id, second.id), ("01-02", second.id, None), ("01-03", second.id, None)]


def test_a_partial_write_replaces_the_features_listed_and_keeps_the_rest(store: MapStore) -> None:
    site = store.ensure_map("site")
    first = store.write_revision(site.id, RevisionWrite("pillars", features={
        "bin": [_bin("01-01", 1, 1), _bin("01-02", 2, 1), _bin("01-03", 3, 1)]}))
    relabelled = Feature("bin", "01-02", {"type": "Point", "coordinates": [2, 1]}, {"aisle": "02"}, 0.9)
    second = store.write_revision(site.id, RevisionWrite("pillars", features={
        "bin": [_bin("01-01", 1, 1), relabelled, _bin("01-04", 4, 1)]}, partial=frozenset({"bin"})))

    live = {f.feature.key: f for f in store.features(site.id, kinds=["bin"])}
    assert sorted(live) == ["01-01", "01-02", "01-03", "01-04"]
    assert live["01-01"].revision_id == live["01-03"].revision_id == first.id
    assert live["01-02"].feature.properties == {"aisle": "02"} and live["01-02"].revision_id == second.id
    assert second.summary["features"]["bin"] == {"added": 1, "removed": 0, "moved": 0, "changed": 1, "total": 4}
    with pytest.raises(StoreError, match="partial kinds"):
        RevisionWrite("pillars", features={"bin": []}, partial=frozenset({"wall"}))


def test_other_stages_features_are_untouched(store: MapStore) -> None:
    site = store.ensure_map("site")
    store.write_revision(site.id, RevisionWrite("pillars", features={"bin": [_bin("A", 0, 0)]}))
    store.write_revision(site.id, RevisionWrite("wms_import", features={"bin": [_bin("B", 5, 5)]}))
    assert sorted(f.feature.key for f in store.features(site.id)) == ["A", "B"]


def test_a_failing_revision_leaves_nothing_behind(store: MapStore, monkeypatch: pytest.MonkeyPatch) -> None:
    site = store.ensure_map("site")
    store.write_revision(site.id, RevisionWrite("pillars", features={"bin": [_bin("A", 0, 0)]}))
    broken = RevisionWrite("pillars", layers=[_grid(1)], features={"bin": [_bin("B", 1, 1)]},
                           topology=([TopologyNode("n", "corridor")], []))

    def fail_last_step(*args: object, **kwargs: object) -> None:
        raise sa.exc.IntegrityError("INSERT", {}, Exception("failure after layers and features were written"))

    monkeypatch.setattr(store, "_replace_topology", fail_last_step)
    with pytest.raises(sa.exc.IntegrityError):
        store.write_revision(site.id, broken)
    assert [f.feature.key for f in store.features(site.id)] == ["A"]
    assert store.layer(site.id, "occupancy") is None
    assert len(store.revisions(site.id)) == 1


def test_a_large_wms_list_is_stored_whole_and_in_order(store: MapStore) -> None:
    site = store.ensure_map("site")
    old = store.replace_wms_bins(site.id, [WmsBin("OLD-1")])
    items = [WmsBin(f"W-{i:05d}", float(i), 2.0, level=i % 4) for i in range(25_001, 0, -1)]
    written = store.replace_wms_bins(site.id, items)
    assert store.wms_bins(site.id) == items
    assert written.summary["wms_bins"] == {"total": 25_001, "previous": 1}
    assert [b.wms_id for b in store.wms_bins(site.id, revision=old.id)] == ["OLD-1"]



def test_a_large_wms_list_with_repeated_ids_is_refused_at_once_and_the_stored_one_kept(store: MapStore) -> None:
    site = store.ensure_map("site")
    store.replace_wms_bins(site.id, [WmsBin("OLD-1")])
    items = [WmsBin(f"W-{i:06d}") for i in range(100_000)] + [WmsBin("W-000007"), WmsBin("W-000003")]
    with pytest.raises(StoreError, match=r"repeated: \['W-000003', 'W-000007'\]"):
        store.replace_wms_bins(site.id, items)
    assert [b.wms_id for b in store.wms_bins(site.id)] == ["OLD-1"]

def test_topology_is_versioned(store: MapStore) -> None:
    site = store.ensure_map("site")
    first = store.write_revision(site.id, RevisionWrite("grid", topology=(
        [TopologyNode("c1", "corridor", 1, 2), TopologyNode("j1", "junction", 3, 2)],
        [TopologyEdge("c1", "j1", {"connection": "connected"})])))
    store.write_revision(site.id, RevisionWrite("grid", topology=([TopologyNode("c2", "corridor")], [])))
    nodes, edges = store.topology(site.id)
    assert [n.key for n in nodes] == ["c2"] and edges == []
    nodes, edges = store.topology(site.id, revision=first.id)
    assert [n.key for n in nodes] == ["c1", "j1"] and edges[0].attributes == {"connection": "connected"}


@pytest.mark.parametrize(("make", "match"), [
    (lambda: Feature("shelf", "x", {"type": "Point", "coordinates": [0, 0]}), "unknown feature kind"),
    (lambda: Feature("bin", "x", {"type": "Point", "coordinates": [float("nan"), 0]}), "finite"),
    (lambda: Feature("bin", "x", {"coordinates": [0, 0]}), "GeoJSON"),
    (lambda: GridLayer("occ", np.zeros((0, 3), np.int8), 0.05, 0, 0), "non-empty 2-D"),
    (lambda: GridLayer("occ", np.zeros((3, 3), np.int8), -1.0, 0, 0), "resolution"),
    (lambda: RevisionWrite("s", features={"bin": [_bin("A", 0, 0), _bin("A", 1, 1)]}), "unique"),
])
def test_bad_records_are_refused_before_touching_the_database(make: object, match: str) -> None:
    with pytest.raises(StoreError, match=match):
        make()  # type: ignore[operator]


def test_readers_are_not_blocked_by_a_writer(store: MapStore) -> None:
    site = store.ensure_map("site")
    store.write_revision(site.id, RevisionWrite("occ", layers=[_grid(1)]))
    writer_inside = threading.Event()
    release = threading.Event()
    with store.engine.connect() as writer:
        transaction = writer.begin()
        writer.execute(sa.text("UPDATE maps SET frame_id = 'held' WHERE id = :id"), {"id": site.id})
        writer_inside.set()
        reader_result: list[object] = []
        reader = threading.Thread(target=lambda: reader_result.append(store.layer(site.id, "occupancy")))
        reader.start()
        reader.join(timeout=5)
        release.set()
        transaction.rollback()
    assert reader_result and reader_result[0] is not None


def test_stop_writes_lets_the_write_under_way_commit_and_refuses_later_ones(store: MapStore) -> None:
    site = store.ensure_map("site")
    with store.engine.connect() as other:  # another writer holds the map: the write waits inside its transaction
        transaction = other.begin()
        other.execute(sa.text("UPDATE maps SET frame_id = 'held' WHERE id = :id"), {"id": site.id})
        written: list[object] = []
        writer = threading.Thread(target=lambda: written.append(
            store.write_revision(site.id, RevisionWrite("occ", layers=[_grid(1)]))))
        writer.start()
        wait_for(lambda: store._writing == 1, what="the write under way")
        stopper = threading.Thread(target=store.stop_writes)
        stopper.start()
        stopper.join(timeout=0.5)
        assert stopper.is_alive()  # waits for the write under way
        transaction.commit()
    writer.join(timeout=30)
    stopper.join(timeout=30)
    assert not stopper.is_alive() and len(written) == 1  # the write under way was committed whole
    with pytest.raises(StoreUnavailableError, match="no more writes"):
        store.write_revision(site.id, RevisionWrite("occ", layers=[_grid(2)]))
    stored = store.layer(site.id, "occupancy")
    assert stored is not None and (stored.layer.data == 1).all()


def test_unreachable_database_is_reported_as_unavailable() -> None:
    store = MapStore("postgresql+psycopg://nobody@127.0.0.1:1/none")
    with pytest.raises(StoreUnavailableError, match="unavailable"):
        store.ping()
    store.close()


def test_heartbeats_upsert_worker_state(store: MapStore) -> None:
    import datetime as dt

    started = dt.datetime.now(dt.UTC)
    store.heartbeat("occupancy_mapping", {"scans": 1}, started_at=started)
    store.heartbeat("occupancy_mapping", {"scans": 5}, started_at=started)
    (worker,) = store.workers()
    assert worker.name == "occupancy_mapping" and worker.counters == {"scans": 5}


def test_upgrade_says_nothing_unless_it_migrates(store_url: str, caplog: pytest.LogCaptureFixture) -> None:
    fresh = MapStore(store_url)
    with caplog.at_level(logging.DEBUG):
        assert fresh.upgrade() is True
        migrated = [r.getMessage() for r in caplog.records]
        caplog.clear()
        assert fresh.upgrade() is False
    fresh.close()

    assert any("Running upgrade" in message for message in migrated)
    assert not any("setup plugin" in message for message in migrated)
    assert [r.getMessage() for r in caplog.records if r.levelno >= logging.INFO] == []
