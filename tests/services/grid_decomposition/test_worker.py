"""The grid-decomposition stage as deployed: occupancy revisions in a real SQLite store, a real zenoh bus."""

from __future__ import annotations

import math
from collections.abc import Iterator
from pathlib import Path

import cv2
import numpy as np
import pytest

from atlas.bins import select_bins
from atlas.cache import RevisionCache
from atlas.navigation import blocking, load_navmap
from services.grid_decomposition import DecompositionError
from services.grid_decomposition.known_racks import footprint_mask, footprints
from services.grid_decomposition.worker import DecompositionStage, decomposition_stage
from services.simulator import World
from shared import messages
from shared.bus import WORKER_NAMESPACE, Bus
from shared.places import LABEL_OVERRIDES_KEY, LABEL_TABLE_STAGE
from shared.settings import DecompositionSettings, Settings, ZenohSettings
from shared.store import Feature, GridLayer, MapStore, Revision, RevisionWrite
from shared.worker import MAP_EVENTS_TOPIC, StageContext, map_event
from tests import stages
from tests.api.warehouse_map import bin_features, warehouse
from tests.helpers import wait_for
from tests.services.grid_decomposition.warehouse import synthetic_warehouse

STAGE = "grid_decomposition"
RES_M = 0.1
ORIGIN_XY_M = (-3.0, 2.0)
REGION_KINDS = ("corridor", "junction", "room", "open_area", "region")
CONNECTIONS = {"connected", "storage_access", "door", "disconnected"}
TIMEOUT_S = 30.0


class _Stages:
    """A factory of stages without a least period between decompositions that keeps the one it built last, to read
    its counters (they follow the map events; the safety poll stays at its default unless ``options`` set it)."""

    def __init__(self, **options: float) -> None:
        self.settings = DecompositionSettings(**{"min_period_s": 0.0} | options)
        self.built: list[DecompositionStage] = []

    def __call__(self, context: StageContext) -> DecompositionStage:
        self.built.append(DecompositionStage(context, self.settings))
        return self.built[-1]

    def count(self, what: str) -> int:
        return self.built[-1].context.counters.get(f"{STAGE}.{what}") if self.built else 0


@pytest.fixture
def store(tmp_path: Path) -> Iterator[MapStore]:
    map_store = MapStore(f"sqlite:///{tmp_path / 'aisle.db'}")
    map_store.upgrade()
    yield map_store
    map_store.close()


@pytest.fixture
def settings(store: MapStore, zenoh_listen: ZenohSettings) -> Settings:
    return Settings(database_url=store.url, zenoh=zenoh_listen)


def _announce(bus: Bus, settings: Settings, revision: Revision) -> Revision:
    """Announce ``revision`` on ``/aisle/map_events``, as every stage and the API do after a write."""
    publisher = bus.publisher(MAP_EVENTS_TOPIC, messages.MAP_EVENT, namespace=WORKER_NAMESPACE)
    publisher.publish(map_event(settings.map_name, revision))
    publisher.close()
    return revision


def _write_occupancy(store: MapStore, settings: Settings, occupancy: np.ndarray, bus: Bus | None = None) -> Revision:
    """Store ``occupancy`` as a revision of the occupancy stage, announced on ``bus`` if given."""
    map_id = store.ensure_map(settings.map_name).id
    layer = GridLayer("occupancy", occupancy.astype(np.int8), RES_M, *ORIGIN_XY_M)
    revision = store.write_revision(map_id, RevisionWrite("occupancy_mapping", layers=[layer]))
    return revision if bus is None else _announce(bus, settings, revision)


def _decompositions(store: MapStore, settings: Settings) -> list[Revision]:
    map_id = store.ensure_map(settings.map_name).id
    return [r for r in store.revisions(map_id, limit=1000) if r.stage == STAGE]


def _wait_decompositions(store: MapStore, settings: Settings, n: int) -> Revision:
    wait_for(lambda: len(_decompositions(store, settings)) >= n, timeout_s=TIMEOUT_S,
             what=f"decomposition revision {n}")
    return _decompositions(store, settings)[n - 1]


def _add_obstacles(occupancy: np.ndarray, fraction: float, seed: int) -> np.ndarray:
    """A copy with free cells turned occupied, as many as ``fraction`` of its obstacle cells."""
    rng = np.random.default_rng(seed)
    out = occupancy.copy()
    free = np.flatnonzero(out.ravel() == 0)
    n = math.ceil(fraction * np.count_nonzero(out > 0))
    out.ravel()[rng.choice(free, size=n, replace=False)] = 100
    return out


def test_worker_decomposes_an_occupancy_revision_into_places_on_free_space(
        store: MapStore, settings: Settings) -> None:
    house = synthetic_warehouse(0, resolution_m=RES_M)
    with stages.running_stage(STAGE, _Stages(), settings, store) as bus:
        source = _write_occupancy(store, settings, house.occupancy, bus)
        revision = _wait_decompositions(store, settings, 1)
    map_id = store.ensure_map(settings.map_name).id
    assert revision.summary["source_revision"] == source.id
    assert set(revision.summary["layers_updated"]) == {"place_labels", "place_segments"}
    labels = store.layer(map_id, "place_labels")
    assert labels is not None and labels.revision_id == revision.id
    assert labels.layer.data.shape == house.occupancy.shape
    assert (labels.layer.origin_x_m, labels.layer.origin_y_m) == ORIGIN_XY_M
    assert labels.layer.meta["encoding"] == "place_labels"

    features = [s.feature for s in store.features(map_id) if s.stage == STAGE]
    kinds = {f.kind for f in features}
    assert {"corridor", "junction", "region"} <= kinds
    assert "storage" in {f.properties["label"] for f in features if f.kind == "region"}
    free = (house.occupancy >= 0) & (house.occupancy < 25)
    for feature in features:
        if feature.kind not in REGION_KINDS:
            continue
        xy = np.array([p for poly in feature.geometry["coordinates"] for ring in poly for p in ring])
        rows = np.floor((xy[:, 1] - ORIGIN_XY_M[1]) / RES_M).astype(int)
        cols = np.floor((xy[:, 0] - ORIGIN_XY_M[0]) / RES_M).astype(int)
        assert np.all((rows >= 0) & (rows < free.shape[0]) & (cols >= 0) & (cols < free.shape[1]))
        assert np.all(free[rows, cols]), f"{feature.kind} {feature.key} has a vertex off free space"

    nodes, edges = store.topology(map_id)
    region_keys = {f.key for f in features if f.kind in REGION_KINDS}
    assert {n.key for n in nodes} == region_keys
    assert edges and {e.attributes["connection"] for e in edges} <= CONNECTIONS


def test_worker_skips_a_small_change_and_takes_a_large_one(store: MapStore, settings: Settings) -> None:
    house = synthetic_warehouse(1, resolution_m=RES_M)
    factory = _Stages(min_change_fraction=0.02)
    with stages.running_stage(STAGE, factory, settings, store) as bus:
        _write_occupancy(store, settings, house.occupancy, bus)
        _wait_decompositions(store, settings, 1)
        small = _add_obstacles(house.occupancy, 0.005, seed=1)
        _write_occupancy(store, settings, small, bus)
        wait_for(lambda: factory.count("small_changes_skipped") == 1, timeout_s=TIMEOUT_S,
                 what="the small change to be seen and skipped")
        assert len(_decompositions(store, settings)) == 1
        large = _add_obstacles(small, 0.1, seed=2)
        source = _write_occupancy(store, settings, large, bus)
        revision = _wait_decompositions(store, settings, 2)
        assert revision.summary["source_revision"] == source.id
        wait_for(lambda: factory.count("decompositions") == 2, what="the second decomposition to be counted")
        assert factory.count("decompositions") == 2 and factory.count("crashes") == 0


def test_worker_counts_an_unknown_grid_and_carries_on(store: MapStore, settings: Settings) -> None:
    house = synthetic_warehouse(2, resolution_m=RES_M)
    factory = _Stages()
    with stages.running_stage(STAGE, factory, settings, store) as bus:
        _write_occupancy(store, settings, np.full((40, 60), -1, dtype=np.int8), bus)
        wait_for(lambda: factory.count("decomposition_errors") == 1, timeout_s=TIMEOUT_S,
                 what="the unknown grid to be counted")
        source = _write_occupancy(store, settings, house.occupancy, bus)
        revision = _wait_decompositions(store, settings, 1)
        assert revision.summary["source_revision"] == source.id
        assert bus.alive_workers() == [STAGE]
        assert factory.count("crashes") == 0
        assert len(factory.built) == 1


def test_restarted_worker_does_not_decompose_the_same_grid_again(store: MapStore, settings: Settings) -> None:
    house = synthetic_warehouse(0, resolution_m=RES_M)
    with stages.running_stage(STAGE, _Stages(), settings, store) as bus:
        _write_occupancy(store, settings, house.occupancy, bus)
        _wait_decompositions(store, settings, 1)
    factory = _Stages(min_change_fraction=0.02)
    with stages.running_stage(STAGE, factory, settings, store) as bus:
        _write_occupancy(store, settings, _add_obstacles(house.occupancy, 0.005, seed=3), bus)
        wait_for(lambda: factory.count("small_changes_skipped") == 1, timeout_s=TIMEOUT_S,
                 what="the small change to be measured against the resumed grid")
    assert len(_decompositions(store, settings)) == 1


def test_worker_decomposes_a_grid_stored_before_it_started(store: MapStore, settings: Settings) -> None:
    """Its event went out while no worker listened: the look at the store on start finds it."""
    house = synthetic_warehouse(0, resolution_m=RES_M)
    source = _write_occupancy(store, settings, house.occupancy)
    with stages.running_stage(STAGE, _Stages(), settings, store):
        revision = _wait_decompositions(store, settings, 1)
    assert revision.summary["source_revision"] == source.id


def test_the_safety_poll_finds_a_revision_no_event_announced(store: MapStore, settings: Settings) -> None:
    """A writer on another bus (or a lost event) announces nothing here: the slow look at the store catches it."""
    house = synthetic_warehouse(1, resolution_m=RES_M)
    factory = _Stages(safety_poll_period_s=0.5)
    with stages.running_stage(STAGE, factory, settings, store):
        wait_for(lambda: bool(factory.built), what="the stage to be built")
        source = _write_occupancy(store, settings, house.occupancy)
        revision = _wait_decompositions(store, settings, 1)
    assert revision.summary["source_revision"] == source.id


def test_stage_factory_starts_the_worker(store: MapStore, settings: Settings) -> None:
    with stages.running_stage(STAGE, decomposition_stage, settings, store):
        pass


@pytest.mark.parametrize("options", [{"min_change_fraction": 1.5}, {"safety_poll_period_s": 0.0},
                                     {"source_layer": "place_labels"}, {"neck_half_width_m": -1.0}])
def test_stage_rejects_nonsense_options(store: MapStore, settings: Settings, options: dict[str, object]) -> None:
    context = StageContext(STAGE, None, store, settings, store.ensure_map(settings.map_name), None)  # type: ignore[arg-type]
    with pytest.raises(DecompositionError):
        DecompositionStage(context, DecompositionSettings.model_construct(**options))  # type: ignore[arg-type]


@pytest.mark.parametrize(("chosen_label", "stored_as"), [("pallet cell", "storage"), ("room", "room")])
def test_a_label_table_revision_relabels_the_map_as_a_new_revision(
        store: MapStore, settings: Settings, chosen_label: str, stored_as: str) -> None:
    house = synthetic_warehouse(0, resolution_m=RES_M)
    map_id = store.ensure_map(settings.map_name).id
    with stages.running_stage(STAGE, _Stages(), settings, store) as bus:
        _write_occupancy(store, settings, house.occupancy, bus)
        first = _wait_decompositions(store, settings, 1)
        before = store.features(map_id, kinds=list(REGION_KINDS))
        labels: dict[int, set[str]] = {}
        for f in before:
            labels.setdefault(f.feature.properties["category"], set()).add(f.feature.properties["label"])
        chosen = min(c for c, names in labels.items() if "storage" in names)
        _announce(bus, settings, store.write_revision(
            map_id, RevisionWrite(LABEL_TABLE_STAGE, summary={LABEL_OVERRIDES_KEY: {str(chosen): chosen_label}})))
        second = _wait_decompositions(store, settings, 2)

    assert second.summary["source_revision"] == first.summary["source_revision"]
    assert second.summary[LABEL_OVERRIDES_KEY] == {str(chosen): stored_as}
    after = store.features(map_id, kinds=list(REGION_KINDS))
    assert len(after) == len(before)  # the override renames places, it keeps the warehouse's regions
    relabelled = [f.feature for f in after if f.feature.properties["category"] == chosen]
    assert relabelled and all(f.properties["label"] == stored_as for f in relabelled)


def _region_at(store: MapStore, map_id: int, x_m: float, y_m: float) -> str:
    """Key of the region whose cell holds (x, y) in the newest segment layer."""
    stored = store.layer(map_id, "place_segments")
    assert stored is not None
    layer = stored.layer
    row = math.floor((y_m - layer.origin_y_m) / layer.resolution_m)
    col = math.floor((x_m - layer.origin_x_m) / layer.resolution_m)
    return f"r{int(layer.data[row, col])}"


def test_region_keys_and_blocks_stay_on_their_places_while_the_map_grows(
        store: MapStore, settings: Settings) -> None:
    house = synthetic_warehouse(0, resolution_m=RES_M)
    width = house.occupancy.shape[1]
    steps = []
    for share in (0.6, 0.8, 1.0):  # the robot sees more of the hall at each step; unseen cells are unknown
        seen = house.occupancy.copy()
        seen[:, int(share * width):] = -1
        steps.append(seen)
    map_id = store.ensure_map(settings.map_name).id
    cache = RevisionCache(size=4)
    with stages.running_stage(STAGE, _Stages(), settings, store) as bus:
        _write_occupancy(store, settings, steps[0], bus)
        _wait_decompositions(store, settings, 1)
        first = {f.feature.key: f.feature for f in store.features(map_id, kinds=list(REGION_KINDS))}
        corridor = next(f for f in first.values() if f.kind == "corridor" and f.properties["area_m2"] > 5.0)
        blocked = blocking.block_region(store, cache, map_id, corridor.key, reason="spill", by=None).block.block
        keys_then = {key: _centre_of(feature) for key, feature in first.items()}
        for n, occupancy in enumerate(steps[1:], start=2):
            _write_occupancy(store, settings, occupancy, bus)
            revision = _wait_decompositions(store, settings, n)
            assert revision.summary["regions_kept"] > 0
    # every region seen in the first half is still there under the same key, at the same place
    kept = sum(1 for key, (x, y) in keys_then.items() if _region_at(store, map_id, x, y) == key)
    assert kept >= 0.8 * len(keys_then)
    assert _region_at(store, map_id, blocked.x_m, blocked.y_m) == corridor.key
    nav = load_navmap(store, map_id)
    [block] = nav.blocks
    assert block.ids is not None and [nav.key(i) for i in block.ids] == [corridor.key]
    assert blocking.unblock_region(store, RevisionCache(size=4), map_id, corridor.key).removed
    segments = store.layer(map_id, "place_segments")
    assert segments is not None
    ids = {int(i) for i in np.unique(segments.layer.data) if i > 0}
    assert segments.layer.meta["next_region_id"] > max(ids), "fresh ids come from above every id handed out"


def _centre_of(feature: Feature) -> tuple[float, float]:
    """A point inside a region feature's largest polygon, well away from its edge (its pole of inaccessibility,
    approximated on a 0.05 m raster)."""
    polygons = [np.asarray(poly[0], dtype=np.float64) for poly in feature.geometry["coordinates"]]
    ring = max(polygons, key=lambda p: float(np.ptp(p[:, 0]) * np.ptp(p[:, 1])))
    lo = ring.min(axis=0)
    step = 0.05
    size = np.ceil((ring.max(axis=0) - lo) / step).astype(int) + 2
    mask = np.zeros((size[1], size[0]), dtype=np.uint8)
    cv2.fillPoly(mask, [np.round((ring - lo) / step).astype(np.int32)], 1)
    dist = cv2.distanceTransform(mask, cv2.DIST_L2, 3)
    row, col = np.unravel_index(int(np.argmax(dist)), dist.shape)
    return float(lo[0] + col * step), float(lo[1] + row * step)


def test_with_the_pillar_stages_racks_every_aisle_is_a_corridor_and_every_bin_in_a_storage_region(
        store: MapStore, settings: Settings) -> None:
    """The demo's case on a small hall: the lidar shows next to nothing of the racks, the pillar stage has them."""
    world, grids = warehouse().world, warehouse().grids
    bins = bin_features(world)
    unseen = footprint_mask(footprints(bins, "bin"), shape=grids.occupancy.shape, resolution_m=grids.resolution_m,
                            origin_xy_m=(grids.origin_x_m, grids.origin_y_m))
    occupancy = GridLayer("occupancy", np.where(unseen, 0, grids.occupancy).astype(np.int8), grids.resolution_m,
                          grids.origin_x_m, grids.origin_y_m)
    aisles = _aisle_features(world)
    map_id = store.ensure_map(settings.map_name).id
    with stages.running_stage(STAGE, _Stages(), settings, store) as bus:
        _announce(bus, settings, store.write_revision(map_id, RevisionWrite("occupancy_mapping", layers=[occupancy])))
        first = _wait_decompositions(store, settings, 1)
        _announce(bus, settings, store.write_revision(map_id, RevisionWrite(
            "pillar_mapping", features={"bin": bins, "corridor": aisles})))
        second = _wait_decompositions(store, settings, 2)
    assert second.summary["source_revision"] == first.summary["source_revision"], "the same grid, decomposed again"
    regions = {f.feature.key: f.feature for f in store.features(map_id, kinds=list(REGION_KINDS))
               if f.stage == STAGE}
    assert not any(f.kind == "room" for f in regions.values())
    segments = store.layer(map_id, "place_segments")
    assert segments is not None
    sections = [(f"aisle-{a.detail['aisle']:02d}", "corridor", a.polygon) for a in world.areas
                if a.kind.name == "CORRIDOR" and isinstance(a.detail.get("aisle"), int)]
    crossings = [(None, "junction", a.polygon) for a in world.areas if a.kind.name == "JUNCTION"]
    for key, kind, polygon in sections + crossings:  # every aisle section a corridor region, every crossing a junction
        strip = footprint_mask([np.asarray(polygon)], shape=segments.layer.data.shape,
                               resolution_m=grids.resolution_m, origin_xy_m=(grids.origin_x_m, grids.origin_y_m))
        ids, counts = np.unique(segments.layer.data[strip & (segments.layer.data > 0)], return_counts=True)
        region = regions[f"r{ids[counts.argmax()]}"]
        assert counts.max() > 0.8 * counts.sum() and region.kind == kind, (key, kind, polygon)
        assert region.properties.get("aisle") == key, "an aisle's corridor regions are named after it"
    nodes, _ = store.topology(map_id)
    assert sorted(n.attributes["aisle"] for n in nodes if "aisle" in n.attributes) == sorted(k for k, _, _ in sections)
    answers = select_bins(store, RevisionCache(size=4), map_id, revision=None, bbox=None, limit=10_000, offset=0)
    assert answers.total == len(bins)
    for answer in answers.bins:
        assert answer.storage_region is not None and answer.storage_region.label == "storage", answer.bin.id
        assert answer.corridor is not None and answer.corridor.key == f"aisle-{answer.bin.aisle:02d}"
        assert answer.nearest_junction is not None


def _aisle_features(world: World) -> list[Feature]:
    """An ``aisle-NN`` corridor per aisle of the world, the rectangle over its sections (as the pillar stage
    spans an aisle from its first bin to its last)."""
    sections: dict[int, list[np.ndarray]] = {}
    for area in world.areas:
        if area.kind.name == "CORRIDOR" and isinstance(area.detail.get("aisle"), int):
            sections.setdefault(area.detail["aisle"], []).append(np.asarray(area.polygon))
    out = []
    for aisle, polygons in sorted(sections.items()):
        xy = np.vstack(polygons)
        (x0, y0), (x1, y1) = xy.min(axis=0), xy.max(axis=0)
        ring = [[x0, y0], [x1, y0], [x1, y1], [x0, y1], [x0, y0]]
        out.append(Feature("corridor", f"aisle-{aisle:02d}", {"type": "Polygon", "coordinates": [ring]},
                           {"kind": "corridor", "label": "corridor", "aisle": aisle}))
    return out
