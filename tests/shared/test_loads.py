"""Bin states and bay scenes as map features, and the writer the load-scene stage stores them with."""

from __future__ import annotations

import dataclasses

import pytest

from shared.loads import (
    LOADS_STAGE,
    Flag,
    LoadRecordError,
    Occupancy,
    Relation,
    SceneEdge,
    SceneWriter,
    occupancy_feature,
    occupancy_from_feature,
    scene_feature,
    scene_from_feature,
    write_scene_revision,
)
from shared.store import Feature, MapStore, RevisionWrite
from tests.loads_data import BAY_1, bay_1_scene, bay_2_scene, first_survey, seen, write_bins


def test_records_read_back_as_written() -> None:
    for record in first_survey():
        assert occupancy_from_feature(occupancy_feature(record, at=(1.0, 2.0))) == record
    scene = bay_1_scene()
    assert scene_from_feature(scene_feature(scene, at=(1.0, 1.0))) == scene


def test_records_that_cannot_be_stored_are_refused_with_the_reason() -> None:
    record = first_survey()[0]
    with pytest.raises(LoadRecordError, match="confidence must be a probability"):
        occupancy_feature(dataclasses.replace(record, confidence=float("nan")), at=(0.0, 0.0))
    with pytest.raises(LoadRecordError, match="finite"):
        occupancy_feature(record, at=(float("inf"), 0.0))
    ghost = SceneEdge("p1", "nobody", Relation.SUPPORTS)
    with pytest.raises(LoadRecordError, match="names a node it lacks"):
        scene_feature(dataclasses.replace(bay_1_scene(), edges=(ghost,)), at=(0.0, 0.0))
    flat = dataclasses.replace(bay_1_scene().nodes[0], size=(1.2, 0.8, 0.0))
    with pytest.raises(LoadRecordError, match="size must be positive"):
        scene_feature(dataclasses.replace(bay_1_scene(), nodes=(flat,)), at=(0.0, 0.0))


def test_writer_stores_what_changed_keeps_the_rest_and_skips_bad_records(store: MapStore) -> None:
    write_bins(store)
    map_id = store.ensure_map("site").id
    first = write_scene_revision(store, map_id, [bay_1_scene(), bay_2_scene()], first_survey())
    assert first.revision is not None and not first.skipped
    assert set(first.bins_changed) == {"01-001-01", "01-001-02", "01-002-01", "01-002-02"}
    rows = {item.feature.key: item.id for item in store.features(map_id, kinds=["bin_state", "load_scene"])}

    again = write_scene_revision(store, map_id, [bay_1_scene()], first_survey()[:2])
    assert again.revision is None, "nothing changed, so no revision"

    bad = dataclasses.replace(first_survey()[1], confidence=float("nan"))
    moved = seen("01-002-02", Occupancy.OCCUPIED, views=2, objects=("p4",), bay="r0-001/2")
    stranger = seen("09-999-01", Occupancy.EMPTY, views=3)
    third = write_scene_revision(store, map_id, [], [bad, moved, stranger])
    assert third.revision is not None
    assert third.bins_changed == ("01-002-02",)
    assert {(s.key, s.reason.split(":")[0]) for s in third.skipped} == {
        ("01-001-02", "bin '01-001-02'"), ("09-999-01", "the map has no bin of this id")}
    live = {item.feature.key: item for item in store.features(map_id, kinds=["bin_state", "load_scene"])}
    assert {key: item.id for key, item in live.items() if key != "01-002-02"} == {
        key: row for key, row in rows.items() if key != "01-002-02"}, "unchanged records stay the rows they were"
    assert occupancy_from_feature(live["01-001-02"].feature).state == Occupancy.EMPTY, "a bad record loses nothing"
    assert all(item.stage == LOADS_STAGE for item in live.values())
    assert third.revision.summary["features"]["bin_state"]["changed"] == 1
    assert third.revision.summary["occupancy_changed"] == ["01-002-02"]
    scene = scene_from_feature(live[BAY_1].feature)
    assert {n.id for n in scene.nodes if Flag.FALSE_ESTIMATE in n.flags} == {"g1"}


def test_a_kept_writer_writes_again_what_a_store_outage_kept_out(store: MapStore) -> None:
    write_bins(store)
    map_id = store.ensure_map("site").id
    writer = SceneWriter(store, map_id)
    assert writer.write([bay_1_scene()], first_survey()).revision is not None
    update = [seen("01-002-02", Occupancy.OCCUPIED, views=2, objects=("p4",), bay="r0-001/2")]

    lost = writer.write([], update, commit=lambda write: None)  # as StageContext.commit when the store is down
    assert lost.revision is None and lost.bins_changed == ()
    retried = writer.write([], update)
    assert retried.revision is not None and retried.bins_changed == ("01-002-02",)
    assert writer.write([], update).revision is None, "written once, then nothing changed"
    live = {item.feature.key for item in store.features(map_id, kinds=["bin_state"])}
    assert live == {record.bin_id for record in first_survey()}

    # the pillar stage moves a bin and adds one: the kept writer places states at the bins as they are now
    moved = Feature("bin", "01-002-02", {"type": "Point", "coordinates": [3.5, 1.0]}, {"id": "01-002-02"}, 0.9)
    added = Feature("bin", "01-004-01", {"type": "Point", "coordinates": [7.0, 1.0]}, {"id": "01-004-01"}, 0.9)
    store.write_revision(map_id, RevisionWrite("pillar_mapping", features={"bin": [moved, added]},
                                               partial=frozenset({"bin"})))
    later = writer.write([], [seen("01-002-02", Occupancy.EMPTY, views=3), seen("01-004-01", Occupancy.EMPTY, views=2)])
    assert not later.skipped
    states = {item.feature.key: item.feature.geometry["coordinates"]
              for item in store.features(map_id, kinds=["bin_state"])}
    assert states["01-002-02"] == [3.5, 1.0] and states["01-004-01"] == [7.0, 1.0]


def test_states_of_bins_the_pillar_stage_removed_are_retired_the_others_stay(store: MapStore) -> None:
    write_bins(store)
    map_id = store.ensure_map("site").id
    writer = SceneWriter(store, map_id)
    assert writer.write([bay_1_scene(), bay_2_scene()], first_survey()).revision is not None
    before = {item.feature.key: item.id for item in store.features(map_id, kinds=["bin_state"])}

    kept = [item.feature for item in store.features(map_id, kinds=["bin"]) if item.feature.key != "01-002-02"]
    store.write_revision(map_id, RevisionWrite("pillar_mapping", features={"bin": kept}))  # the bin is gone
    update = [seen("01-001-02", Occupancy.OCCUPIED, views=3, objects=("p9",), bay=BAY_1)]
    written = writer.write([], update)
    assert written.revision is not None and written.revision.summary["bin_states_retired"] == 1
    live = {item.feature.key: item for item in store.features(map_id, kinds=["bin_state"])}
    assert set(live) == set(before) - {"01-002-02"}
    assert occupancy_from_feature(live["01-001-02"].feature).objects == ("p9",)
    assert live["01-001-01"].id == before["01-001-01"], "the other states stay the rows they were"
    assert writer.write([], update).revision is None, "retired once"
    assert SceneWriter(store, map_id).write([], update).revision is None, "a fresh writer finds nothing to retire"
    previous = written.revision.id - 1
    as_was = {item.feature.key for item in store.features(map_id, kinds=["bin_state"], revision=previous)}
    assert "01-002-02" in as_was, "nothing stored is lost: the state is in the history"
