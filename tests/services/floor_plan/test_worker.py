"""The floor-plan worker: an occupancy revision in, one revision of units, doors and their graph out."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import numpy as np
import numpy.typing as npt
import pytest

from services.floor_plan.worker import FloorPlanStage
from shared import messages
from shared.bus import WORKER_NAMESPACE, Bus
from shared.robots import Robot, TrackPoint
from shared.settings import FloorPlanStageSettings, Settings, ZenohSettings
from shared.store import GridLayer, MapStore, Revision, RevisionWrite
from shared.vocabulary import FeatureKind
from shared.worker import MAP_EVENTS_TOPIC, StageContext, map_event
from tests import stages
from tests.helpers import wait_for

STAGE = "floor_plan"
RES_M = 0.05
TIMEOUT_S = 60.0


def _stage(context: StageContext) -> FloorPlanStage:
    return FloorPlanStage(context, FloorPlanStageSettings(min_period_s=0.0, iterations=4500, warm_iterations=3500))


@pytest.fixture
def store(tmp_path: Path) -> Iterator[MapStore]:
    map_store = MapStore(f"sqlite:///{tmp_path / 'aisle.db'}")
    map_store.upgrade()
    yield map_store
    map_store.close()


@pytest.fixture
def settings(store: MapStore, zenoh_listen: ZenohSettings) -> Settings:
    return Settings(database_url=store.url, zenoh=zenoh_listen)


def _box(occ: npt.NDArray[np.int8], r0: int, r1: int, c0: int, c1: int) -> None:
    occ[r0 : r1 + 1, c0 : c1 + 1] = 100
    occ[r0 + 2 : r1 - 1, c0 + 2 : c1 - 1] = 0


def _write(store: MapStore, settings: Settings, bus: Bus, occ: npt.NDArray[np.int8],
           origin: tuple[float, float], robots: tuple[Robot, ...] = ()) -> Revision:
    map_id = store.ensure_map(settings.map_name).id
    revision = store.write_revision(map_id, RevisionWrite(
        "occupancy_mapping", layers=[GridLayer("occupancy", occ, RES_M, *origin)],
        features={FeatureKind.ROBOT: [r.feature() for r in robots]} if robots else {}))
    publisher = bus.publisher(MAP_EVENTS_TOPIC, messages.MAP_EVENT, namespace=WORKER_NAMESPACE)
    publisher.publish(map_event(settings.map_name, revision))
    publisher.close()
    return revision


def _plans(store: MapStore, settings: Settings) -> list[Revision]:
    map_id = store.ensure_map(settings.map_name).id
    return [r for r in store.revisions(map_id, limit=1000) if r.stage == STAGE]


def test_worker_writes_units_doors_and_graph_and_keeps_ids_as_the_map_grows(
        store: MapStore, settings: Settings) -> None:
    occ = np.full((80, 120), -1, np.int8)
    _box(occ, 10, 69, 10, 60)
    _box(occ, 10, 69, 59, 109)
    occ[35:48, 59:61] = 0
    grown = np.full((80, 180), -1, np.int8)  # the map grows by 3 m to the left: its origin moves
    grown[:, 60:] = occ
    _box(grown, 10, 69, 19, 70)
    grown[30:42, 69:71] = 0
    map_id = store.ensure_map(settings.map_name).id
    with stages.running_stage(STAGE, _stage, settings, store) as bus:
        source = _write(store, settings, bus, occ, (-1.0, 2.0))
        wait_for(lambda: len(_plans(store, settings)) >= 1, timeout_s=TIMEOUT_S, what="the first floor plan")
        first = {s.feature.key: s.feature for s in store.features(map_id) if s.stage == STAGE}
        _write(store, settings, bus, grown, (-4.0, 2.0))
        wait_for(lambda: len(_plans(store, settings)) >= 2, timeout_s=TIMEOUT_S, what="the second floor plan")
    revision = _plans(store, settings)[0]
    assert revision.summary["source_revision"] == source.id
    units = [f for f in first.values() if f.kind == "unit"]
    doors = [f for f in first.values() if f.kind == "door"]
    assert len(units) == 2 and len(doors) == 1
    assert set(doors[0].properties["units"]) == {u.key for u in units}
    assert all(u.properties["label"] == "room" for u in units)

    second = _plans(store, settings)[1]
    assert second.summary["warm_start"] is True
    now = {s.feature.key: s.feature for s in store.features(map_id) if s.stage == STAGE and s.feature.kind == "unit"}
    assert {u.key for u in units} <= set(now), "units that still exist keep their ids"
    assert len(now) == 3
    layer = store.layer(map_id, "floor_plan")
    assert layer is not None and layer.layer.data.shape == grown.shape
    assert layer.layer.meta["source_revision"] == second.summary["source_revision"]
    meta = layer.layer.meta
    assert meta["k"] >= meta["k_units"] and meta["wall_segments"] >= 0, "fitted walls never explain the map worse"
    nodes, edges = store.topology(map_id)
    assert {n.key for n in nodes} == set(now)
    assert {e.attributes["connection"] for e in edges} <= {"door", "wall"}


def test_a_restarted_worker_warm_starts_from_the_last_stored_world(store: MapStore, settings: Settings) -> None:
    occ = np.full((80, 120), -1, np.int8)
    _box(occ, 10, 69, 10, 60)
    _box(occ, 10, 69, 59, 109)
    occ[35:48, 59:61] = 0
    grown = np.full((80, 180), -1, np.int8)
    grown[:, 60:] = occ
    _box(grown, 10, 69, 19, 70)
    grown[30:42, 69:71] = 0
    map_id = store.ensure_map(settings.map_name).id
    with stages.running_stage(STAGE, _stage, settings, store) as bus:
        _write(store, settings, bus, occ, (-1.0, 2.0))
        wait_for(lambda: len(_plans(store, settings)) >= 1, timeout_s=TIMEOUT_S, what="the first floor plan")
    before = {s.feature.key for s in store.features(map_id) if s.stage == STAGE and s.feature.kind == "unit"}
    with stages.running_stage(STAGE, _stage, settings, store) as bus:  # a new worker: nothing in memory
        _write(store, settings, bus, grown, (-4.0, 2.0))
        wait_for(lambda: len(_plans(store, settings)) >= 2, timeout_s=TIMEOUT_S, what="the plan after the restart")
    after = _plans(store, settings)[1]
    assert after.summary["warm_start"] is True
    now = {s.feature.key for s in store.features(map_id) if s.stage == STAGE and s.feature.kind == "unit"}
    assert len(before) == 2 and before <= now, "units of the world before the restart keep their ids"


def test_the_positions_robots_passed_are_kept_with_the_plan(store: MapStore, settings: Settings) -> None:
    occ = np.full((80, 120), -1, np.int8)
    _box(occ, 10, 69, 10, 60)
    _box(occ, 10, 69, 59, 109)
    occ[35:48, 59:61] = 0
    track = tuple(TrackPoint(x, 3.5, 0.0, int(1e9 * i)) for i, x in enumerate((1.0, 2.0, 3.0, 4.0)))
    robot = Robot("robot1", track[-1], track)
    map_id = store.ensure_map(settings.map_name).id
    with stages.running_stage(STAGE, _stage, settings, store) as bus:
        _write(store, settings, bus, occ, (0.0, 0.0), robots=(robot,))
        wait_for(lambda: len(_plans(store, settings)) >= 1, timeout_s=TIMEOUT_S, what="the floor plan")
    layer = store.layer(map_id, "floor_plan")
    assert layer is not None
    kept = {tuple(p) for p in layer.layer.meta["robot_positions"]}
    assert {(p.x_m, p.y_m) for p in track} <= kept, "every place the robot passed is kept for the next plan"
