import gtsam
import numpy as np
import pytest

from services.semantic_fusion import PoseGraph, SemanticFusionError, se2


def _square(n_side: int = 10, step: float = 1.0) -> np.ndarray:
    poses = [np.zeros(3)]
    for i in range(4 * n_side):
        turn = np.pi / 2 if (i + 1) % n_side == 0 else 0.0
        poses.append(se2.compose(poses[-1], [step, 0.0, turn]))
    return np.array(poses)


def test_loop_closure_pulls_a_drifted_square_back() -> None:
    truth = _square()
    rng = np.random.default_rng(0)
    increments = se2.between(truth[:-1], truth[1:]) + np.column_stack(
        [rng.normal(0, 0.01, 40), rng.normal(0, 0.01, 40), np.full(40, 0.01)])
    odometry = [truth[0]]
    for inc in increments:
        odometry.append(se2.compose(odometry[-1], inc))
    graph = PoseGraph()
    for pose in odometry:
        graph.add_keyframe(pose)
    drift = np.hypot(*(graph.poses[-1, :2] - truth[-1, :2]))
    graph.add_loop_closure(0, 40, se2.between(truth[0], truth[40]))
    graph.add_loop_closure(1, 39, se2.between(truth[1], truth[39]))
    poses = graph.optimise()
    assert np.hypot(*(poses[-1, :2] - truth[-1, :2])) < 0.1 * drift
    assert np.max(np.hypot(*(poses[:, :2] - truth[:, :2]).T)) < drift


def test_pose_prior_moves_the_keyframe_it_names() -> None:
    graph = PoseGraph()
    for x in range(5):
        graph.add_keyframe([float(x), 0.0, 0.0])
    graph.add_pose_prior(4, [4.0, 1.0, 0.0], sigmas=(0.001, 0.001, 0.001))
    poses = graph.optimise()
    assert poses[4, 1] == pytest.approx(1.0, abs=0.01)
    assert abs(poses[0, 1]) < 0.05  # the anchored first keyframe barely moves


def test_pose_graph_rejects_unknown_keyframes_and_bad_noise() -> None:
    graph = PoseGraph()
    graph.add_keyframe([0.0, 0.0, 0.0])
    with pytest.raises(SemanticFusionError, match="does not exist"):
        graph.add_loop_closure(0, 3, [1.0, 0.0, 0.0])
    with pytest.raises(SemanticFusionError, match="sigmas"):
        graph.add_pose_prior(0, [0.0, 0.0, 0.0], sigmas=(0.1, -1.0, 0.1))
    with pytest.raises(SemanticFusionError, match="max_iterations"):
        graph.optimise(max_iterations=0)
    with pytest.raises(SemanticFusionError, match="relinearize_threshold"):
        PoseGraph(relinearize_threshold=0.0)


def test_incremental_optimum_matches_a_batch_solve_of_the_same_graph() -> None:
    truth = _square()
    rng = np.random.default_rng(1)
    increments = se2.between(truth[:-1], truth[1:]) + np.column_stack(
        [rng.normal(0, 0.02, 40), rng.normal(0, 0.02, 40), np.full(40, 0.01)])
    graph = PoseGraph()
    batch = gtsam.NonlinearFactorGraph()
    initial = gtsam.Values()
    match_information = np.array([[400.0, 50.0, 0.0], [50.0, 100.0, 0.0], [0.0, 0.0, 2500.0]])
    pose = truth[0]
    for key in range(41):
        pose = pose if key == 0 else se2.compose(pose, increments[key - 1])
        graph.add_keyframe(pose)
        initial.insert(key, gtsam.Pose2(*pose))
        if key == 0:
            anchor = gtsam.noiseModel.Diagonal.Sigmas([0.005, 0.005, 0.001])  # PoseGraph's default
            batch.add(gtsam.PriorFactorPose2(0, gtsam.Pose2(*pose), anchor))
            continue
        batch.add(gtsam.BetweenFactorPose2(key - 1, key, gtsam.Pose2(*increments[key - 1]),
                                           gtsam.noiseModel.Diagonal.Sigmas(graph.odometry_sigmas(key))))
        if key % 2:  # a scan match, truer than odometry
            relative = se2.between(truth[key - 1], truth[key])
            graph.add_scan_match(key - 1, key, relative, match_information)
            batch.add(gtsam.BetweenFactorPose2(key - 1, key, gtsam.Pose2(*relative),
                                               gtsam.noiseModel.Gaussian.Information(match_information)))
        if key % 8 == 0:
            graph.optimise()  # incremental steps along the way
    graph.add_loop_closure(20, 40, [3.0, 1.0, 0.5])  # a wrong closure, optimised with, then dropped
    graph.optimise()
    graph.remove_loop_closure(0)
    for from_key, to_key in ((0, 40), (1, 39)):
        relative = se2.between(truth[from_key], truth[to_key])
        graph.add_loop_closure(from_key, to_key, relative)
        batch.add(gtsam.BetweenFactorPose2(from_key, to_key, gtsam.Pose2(*relative),
                                           gtsam.noiseModel.Diagonal.Sigmas([0.05, 0.05, 0.01])))
    expected = gtsam.utilities.extractPose2(gtsam.LevenbergMarquardtOptimizer(batch, initial).optimize())
    np.testing.assert_allclose(graph.optimise(), expected, atol=1e-4)
    assert np.max(np.hypot(*(expected[:, :2] - graph.odometry_poses[:, :2]).T)) > 0.1  # the closure mattered
