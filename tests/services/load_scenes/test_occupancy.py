import numpy as np
import pytest

from services.load_scenes import BinEvidence, SceneError, bin_evidence, bin_occupancy, fuse_occupancy, infer_scene
from services.load_scenes import synthetic as syn
from services.load_scenes.boxes import to_map_frame
from services.load_scenes.model import Bay, DepthEvidence, Flag, ObjectKind, Occupancy, SceneGraph, SceneNode

BAY = Bay(key="R1/001", row="R1", aisle=1, bay=1, origin=(0.0, 0.0), yaw_rad=0.0, width_m=2.7, depth_m=1.2,
          levels_z_m=(0.0, 1.6, 3.2), bin_ids=("R1-001-00", "R1-001-01", "R1-001-02"))


def _node(node_id: str, kind: ObjectKind, level: int, p: float = 0.8,
          flags: frozenset[Flag] = frozenset()) -> SceneNode:
    z = BAY.levels_z_m[level] + 0.3
    return SceneNode(id=node_id, kind=kind, centre=(0.6, 0.0, z), size=(0.8, 1.2, 0.6), yaw_rad=0.0, level=level,
                     flags=flags, probability=p)


GRAPH = SceneGraph(bay=BAY.key, stamp_ns=42, nodes=(
    _node("p0", ObjectKind.PALLET, 0), _node("l0", ObjectKind.LOAD, 0),
    _node("ghost", ObjectKind.PALLET, 1, p=0.02, flags=frozenset({Flag.FALSE_ESTIMATE}))), edges=())


def test_bins_are_occupied_empty_or_unknown_when_unseen() -> None:
    seen = BinEvidence(rays=np.array([80, 60, 0]), unexplained=np.zeros(3, np.int64))
    bins = bin_occupancy(BAY, GRAPH, seen)
    assert [b.state for b in bins] == [Occupancy.OCCUPIED, Occupancy.EMPTY, Occupancy.UNKNOWN]
    assert bins[0].objects == ("p0", "l0") and bins[0].last_seen_ns == 42 and bins[0].views == 1
    assert bins[1].objects == () and bins[1].confidence > 0.9
    assert bins[2].last_seen_ns is None and bins[2].views == 0


def test_points_no_box_explains_make_a_bin_occupied() -> None:
    evidence = BinEvidence(rays=np.array([80, 60, 50]), unexplained=np.array([0, 0, 40]))
    assert bin_occupancy(BAY, GRAPH, evidence)[2].state == Occupancy.OCCUPIED


def test_two_agreeing_views_are_surer_and_one_clear_change_flips_the_bin() -> None:
    full = bin_occupancy(BAY, GRAPH, BinEvidence(rays=np.array([80, 60, 0]), unexplained=np.zeros(3, np.int64)))
    empty_graph = SceneGraph(bay=BAY.key, nodes=(), edges=(), stamp_ns=99)
    empty = bin_occupancy(BAY, empty_graph, BinEvidence(rays=np.array([80, 60, 0]), unexplained=np.zeros(3, np.int64)))
    twice = fuse_occupancy(full[0], full[0])
    assert twice.state == Occupancy.OCCUPIED and twice.confidence > full[0].confidence and twice.views == 2
    changed = fuse_occupancy(twice, empty[0])
    assert changed.state == Occupancy.EMPTY and changed.last_seen_ns == 99 and changed.views == 3
    assert fuse_occupancy(twice, empty[2]) is twice  # not seen: nothing learnt
    with pytest.raises(SceneError, match="cannot fuse"):
        fuse_occupancy(full[0], full[1])


def test_bins_above_a_camera_that_sees_low_levels_only_are_unknown_and_the_rest_right() -> None:
    noise = syn.NoiseModel(limited_view_rate=1.0)
    for k in range(40):
        sb = syn.synthetic_bay(3, k, noise)
        if len(sb.bay.levels_z_m) >= 4:
            break
    graph = infer_scene(sb.bay, sb.estimates, sb.evidence)
    bins = bin_occupancy(sb.bay, graph, bin_evidence(sb.bay, graph, sb.evidence))
    assert bins[-1].state == Occupancy.UNKNOWN
    truth = sb.occupied()
    for level in (0, 1):
        assert bins[level].state == (Occupancy.OCCUPIED if truth[level] else Occupancy.EMPTY)


def test_a_graph_of_another_bay_is_refused() -> None:
    other = SceneGraph(bay="R9/009", nodes=(), edges=(), stamp_ns=0)
    with pytest.raises(SceneError, match="R9/009"):
        bin_occupancy(BAY, other, BinEvidence(rays=np.zeros(3, np.int64), unexplained=np.zeros(3, np.int64)))


def test_the_underside_of_a_pallet_on_the_beams_does_not_fill_the_empty_bin_below() -> None:
    rng = np.random.default_rng(3)
    n = 300
    floor = np.column_stack([rng.uniform(-1.2, 1.2, n), rng.uniform(0.1, 1.1, n), np.zeros(n)])
    underside = np.column_stack([rng.uniform(-1.0, 1.0, 40), rng.uniform(0.6, 1.0, 40),
                                 BAY.levels_z_m[1] - rng.uniform(0.0, 0.01, 40)])  # pallet bottom, noise below
    origin = to_map_frame(BAY, np.array([[0.0, -2.6, 0.6]]))[0]
    view = DepthEvidence(origin=tuple(origin), points=to_map_frame(BAY, np.vstack([floor, underside])), stamp_ns=5)
    nothing = SceneGraph(bay=BAY.key, nodes=(), edges=(), stamp_ns=5)
    evidence = bin_evidence(BAY, nothing, [view])
    assert evidence.rays[0] > 0 and evidence.unexplained[0] == 0
    assert bin_occupancy(BAY, nothing, evidence)[0].state == Occupancy.EMPTY
