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
