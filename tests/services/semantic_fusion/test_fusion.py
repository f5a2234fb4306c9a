import numpy as np
import pytest

from services.semantic_fusion import (
    DYNAMIC_CLASSES,
    FusionSettings,
    ScanObservation,
    SemanticFusion,
    SemanticFusionError,
    absolute_trajectory_error,
    infer_labels,
    label_accuracy,
    rasterise,
    se2,
)
from services.semantic_fusion import synthetic as syn
from services.semantic_fusion.fusion import voxel_centroids


@pytest.fixture(scope="module")
def small_run() -> tuple[syn.Warehouse, syn.SimulatedRun]:
    warehouse = syn.make_warehouse(length_m=30.0, width_m=18.0, seed=3)
    return warehouse, syn.simulate_run(warehouse, seed=4, max_scans=400)


def test_reprojection_matches_a_grid_built_at_the_final_poses(small_run) -> None:  # type: ignore[no-untyped-def]
    _, run = small_run
    fusion = SemanticFusion(detect_loops=False)
    for scan in run.scans[:300]:
        fusion.add_scan(scan)
    keys = np.arange(10, fusion.graph.n_keyframes)
    fusion.add_pose_correction(int(fusion.keyframe_stamps_ns[-1]), fusion.graph.poses[-1] + [0.4, -0.2, 0.03],
                               sigmas=(0.01, 0.01, 0.001))
    stamps = fusion.keyframe_stamps_ns
    fresh = SemanticFusion(detect_loops=False)  # fed the corrected poses from the start
    for scan in run.scans[:300]:
        k = int(np.searchsorted(stamps, scan.stamp_ns, side="right")) - 1
        corrected = se2.compose(fusion.graph.poses[k], se2.between(fusion.graph.odometry_poses[k], scan.camera_pose))
        fresh.add_scan(scan._replace(camera_pose=corrected))
    now = fusion.last_stamp_ns * 1e-9  # type: ignore[operator]
    a, b = fusion.layers(), fresh.layers()
    assert keys.size and a.labels.shape == b.labels.shape
    assert np.mean(a.labels == b.labels) > 0.999
    cells_a, cells_b = fusion.grid.cells(now_s=now), fresh.grid.cells(now_s=now)
    assert np.isclose(cells_a.hits.sum(), cells_b.hits.sum(), rtol=1e-5)


def test_fusion_rejects_scans_out_of_order(small_run) -> None:  # type: ignore[no-untyped-def]
    _, run = small_run
    fusion = SemanticFusion(detect_loops=False)
    fusion.add_scan(run.scans[1])
    with pytest.raises(SemanticFusionError, match="not after"):
        fusion.add_scan(run.scans[0])


def test_fusion_settings_reject_nonsense() -> None:
    with pytest.raises(SemanticFusionError, match="positive"):
        FusionSettings(resolution_m=-0.05)


@pytest.mark.slow
def test_loop_closure_and_inference_on_a_simulated_run() -> None:
    warehouse = syn.make_warehouse(length_m=30.0, width_m=18.0, seed=0)
    run = syn.simulate_run(warehouse, seed=100)
    truth = syn.truth_labels(warehouse, resolution_m=0.05)
    fusion = SemanticFusion()
    for scan in run.scans:
        fusion.add_scan(scan)
    stamps = np.array([s.stamp_ns for s in run.scans])
    truth_kf = run.true_poses[np.searchsorted(stamps, fusion.keyframe_stamps_ns)]
    assert fusion.graph.loop_closures
    assert absolute_trajectory_error(fusion.graph.poses, truth_kf) < 0.5 * absolute_trajectory_error(
        fusion.graph.odometry_poses, truth_kf)
    cells = fusion.grid.cells(now_s=fusion.last_stamp_ns * 1e-9)  # type: ignore[operator]
    result = infer_labels(cells)
    inferred = label_accuracy(rasterise(cells, result, resolution_m=0.05), truth, exclude=DYNAMIC_CLASSES)
    raw = label_accuracy(rasterise(cells, result._replace(labels=result.raw_labels), resolution_m=0.05), truth,
                         exclude=DYNAMIC_CLASSES)
    assert inferred.fraction >= raw.fraction
    assert inferred.fraction > 0.9


def test_fusions_sharing_a_grid_reproject_only_their_own_points(small_run) -> None:  # type: ignore[no-untyped-def]
    _, run = small_run
    first, second = run.scans[:150], run.scans[150:300]
    correction = [0.5, 0.3, 0.05]

    def fill(fusion: SemanticFusion, scans: list[ScanObservation], *, correct: bool) -> None:
        for scan in scans:
            fusion.add_scan(scan)
        if correct:  # optimise and re-project every moved keyframe, after the other robot wrote its points
            fusion.add_pose_correction(int(fusion.keyframe_stamps_ns[-1]), fusion.graph.poses[-1] + correction,
                                       sigmas=(0.01, 0.01, 0.001))

    mover = SemanticFusion(detect_loops=False)
    other = SemanticFusion(detect_loops=False, grid=mover.grid)
    fill(mover, first, correct=False)
    fill(other, second, correct=False)
    fill(mover, [], correct=True)
    mover_alone, other_alone = SemanticFusion(detect_loops=False), SemanticFusion(detect_loops=False)
    fill(mover_alone, first, correct=True)
    fill(other_alone, second, correct=False)

    def totals(*fusions: SemanticFusion) -> dict[tuple[int, int], np.ndarray]:
        out: dict[tuple[int, int], np.ndarray] = {}
        for fusion in fusions:
            cells = fusion.grid.cells(now_s=run.scans[299].stamp_ns * 1e-9)
            values = np.column_stack([cells.log_evidence, cells.hits])
            for rc, row in zip(map(tuple, cells.rows_cols.tolist()), values, strict=True):
                out[rc] = out.get(rc, 0.0) + row
        return {rc: v for rc, v in out.items() if v[-1] > 1e-3}

    shared, separate = totals(mover), totals(mover_alone, other_alone)
    assert shared.keys() == separate.keys()
    np.testing.assert_allclose(np.array([shared[k] for k in separate]), np.array(list(separate.values())),
                               atol=1e-3)


def test_a_shared_grid_must_have_the_settings_resolution() -> None:
    with pytest.raises(SemanticFusionError, match="grid resolution"):
        SemanticFusion(FusionSettings(resolution_m=0.1), grid=SemanticFusion().grid)


def _keyframe_truth(fusion: SemanticFusion, run: syn.SimulatedRun) -> np.ndarray:
    stamps = np.array([s.stamp_ns for s in run.scans])
    return run.true_poses[np.searchsorted(stamps, fusion.keyframe_stamps_ns)]


def _fused(run: syn.SimulatedRun, *, lidar: bool, long_baseline: int = 0) -> SemanticFusion:
    fusion = SemanticFusion(FusionSettings(sequential_long_baseline_keyframes=long_baseline))
    ranges = {r.stamp_ns: r for r in run.range_scans} if lidar else {}
    for scan in run.scans:
        fusion.add_scan(scan)
        if scan.stamp_ns in ranges:
            fusion.add_range_scan(ranges[scan.stamp_ns])
    return fusion


@pytest.fixture(scope="module")
def drifting_run() -> syn.SimulatedRun:
    """A whole route through a small hall with four times the usual yaw bias, and a lidar."""
    warehouse = syn.make_warehouse(length_m=30.0, width_m=18.0, seed=0)
    return syn.simulate_run(warehouse, seed=100, odometry_yaw_bias_per_m=0.002, lidar_beams=541)


@pytest.mark.parametrize("long_baseline", [0, FusionSettings().sequential_long_baseline_keyframes])
def test_lidar_slam_brings_the_trajectory_error_down_to_a_grid_cell(drifting_run: syn.SimulatedRun,
                                                                    long_baseline: int) -> None:
    fusion = _fused(drifting_run, lidar=True, long_baseline=long_baseline)
    truth = _keyframe_truth(fusion, drifting_run)
    odometry = absolute_trajectory_error(fusion.graph.odometry_poses, truth)
    slam = absolute_trajectory_error(fusion.graph.poses, truth)
    assert fusion.graph.loop_closures and fusion.graph.n_scan_matches > 0.9 * fusion.graph.n_keyframes
    if long_baseline:  # every fourth keyframe also tied to the one 10 m back
        assert fusion.graph.n_scan_matches > 1.1 * fusion.graph.n_keyframes
    assert odometry > 0.5
    assert slam < 0.05  # one 5 cm cell: the map's own resolution
    assert np.max(np.hypot(*(fusion.graph.poses[:, :2] - truth[:, :2]).T)) < 0.1


def test_a_loop_closure_the_graph_disagrees_with_is_dropped(small_run) -> None:  # type: ignore[no-untyped-def]
    _, run = small_run
    fusion = SemanticFusion()
    for scan in run.scans[:200]:
        fusion.add_scan(scan)
    last = fusion.graph.n_keyframes - 1
    good_poses = fusion.graph.optimise()
    wrong = se2.between(good_poses[last - 20], good_poses[last]) + np.array([2.0, 0.0, 0.0])
    fusion.graph.add_loop_closure(last - 20, last, wrong)
    fusion.graph.optimise()
    error = fusion.graph.constraint_error(fusion.graph.loop_closures[-1])
    assert np.hypot(error[0], error[1]) > fusion.settings.loop_max_residual_m  # sequential matches resist it
    removed = fusion.graph.remove_loop_closure(len(fusion.graph.loop_closures) - 1)
    assert removed.to_key == last
    np.testing.assert_allclose(fusion.graph.optimise(), good_poses, atol=1e-3)


def test_thinned_lidar_points_stay_on_the_surface_they_sample() -> None:
    rng = np.random.default_rng(0)
    along = np.sort(rng.uniform(0.0, 4.0, 400))
    wall = np.column_stack([along, np.full(along.size, 2.02) + rng.normal(0.0, 0.002, along.size)])
    thinned = voxel_centroids(wall, 0.05)
    assert 70 <= thinned.shape[0] <= 81  # about one point per 5 cm of wall
    np.testing.assert_allclose(thinned[:, 1], 2.02, atol=0.005)
    # each kept point is the middle of what its cell saw, not one end of it: no drift along the wall
    cells = np.floor(wall / 0.05).astype(int)
    for point in thinned[:5]:
        same = np.all(cells == np.floor(point / 0.05).astype(int), axis=1)
        np.testing.assert_allclose(point, wall[same].mean(axis=0))
