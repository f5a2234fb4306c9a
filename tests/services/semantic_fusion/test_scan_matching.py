import numpy as np
import pytest

from services.semantic_fusion import SemanticFusionError, align_scans, match_scans, se2


def _structure(rng: np.random.Generator) -> np.ndarray:
    wall = np.column_stack([np.linspace(0, 8, 160), np.zeros(160)])
    side = np.column_stack([np.zeros(80), np.linspace(0, 4, 80)])
    posts = np.repeat(rng.uniform([1, 1], [7, 3], (6, 2)), 6, axis=0) + rng.normal(0, 0.02, (36, 2))
    return np.vstack([wall, side, posts])


@pytest.mark.parametrize("seed", range(3))
def test_match_scans_recovers_a_known_offset(seed: int) -> None:
    rng = np.random.default_rng(seed)
    target = _structure(rng)
    truth = np.array([rng.uniform(-0.8, 0.8), rng.uniform(-0.8, 0.8), rng.uniform(-0.08, 0.08)])
    source = se2.transform_points(se2.inverse(truth), target) + rng.normal(0, 0.01, target.shape)
    match = match_scans(source, target, search_radius_m=1.0, search_angle_rad=0.1)
    np.testing.assert_allclose(match.pose[:2], truth[:2], atol=0.03)
    assert abs(match.pose[2] - truth[2]) < 0.01
    assert match.inlier_fraction > 0.95


def test_match_scans_rejects_tiny_inputs() -> None:
    with pytest.raises(SemanticFusionError, match=">= 3 points"):
        match_scans(np.zeros((2, 2)), np.zeros((10, 2)))


@pytest.mark.parametrize("seed", range(3))
def test_align_scans_recovers_a_small_offset_and_says_how_sure_it_is(seed: int) -> None:
    rng = np.random.default_rng(seed)
    target = _structure(rng)
    truth = np.array([rng.uniform(-0.05, 0.05), rng.uniform(-0.05, 0.05), rng.uniform(-0.01, 0.01)])
    source = se2.transform_points(se2.inverse(truth), target) + rng.normal(0, 0.01, target.shape)
    alignment = align_scans(source, target, initial_pose=np.zeros(3))
    error = se2.between(truth, alignment.pose)
    np.testing.assert_allclose(error[:2], 0.0, atol=0.01)
    assert abs(error[2]) < 0.002
    assert alignment.inlier_fraction > 0.95
    sigmas = np.sqrt(np.diag(np.linalg.inv(alignment.information)))
    assert np.all(np.abs(error) < 5 * sigmas)  # the information is not wildly overconfident


def test_align_scans_leaves_the_direction_along_a_lone_wall_to_the_prior() -> None:
    rng = np.random.default_rng(0)
    wall = np.column_stack([np.linspace(0, 8, 80), np.zeros(80)])  # a point every 10 cm, as a scan sees it
    target = wall + rng.normal(0, 0.01, wall.shape)
    truth = np.array([0.3, 0.05, 0.0])  # 0.3 m along the wall: nothing in the points shows it
    source = se2.transform_points(se2.inverse(truth), wall) + rng.normal(0, 0.01, wall.shape)
    prior = np.diag([1 / 0.1**2, 1 / 0.1**2, 1 / 0.01**2])
    alignment = align_scans(source, target, initial_pose=np.zeros(3), prior_information=prior)
    assert abs(alignment.pose[0]) < 0.05  # stays at the prior along the wall
    assert abs(alignment.pose[1] - truth[1]) < 0.01  # across the wall the points decide
    sigma_along, sigma_across = np.sqrt(np.diag(np.linalg.inv(alignment.information)))[:2]
    assert sigma_along > 10 * sigma_across


def test_align_scans_rejects_bad_input() -> None:
    with pytest.raises(SemanticFusionError, match=">= 3 points"):
        align_scans(np.zeros((2, 2)), np.zeros((10, 2)), initial_pose=np.zeros(3))
    with pytest.raises(SemanticFusionError, match="finite"):
        align_scans(np.full((5, 2), np.nan), np.zeros((10, 2)), initial_pose=np.zeros(3))
