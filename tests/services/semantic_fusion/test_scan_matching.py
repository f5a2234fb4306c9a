import numpy as np
import pytest

from services.semantic_fusion import SemanticFusionError, match_scans, se2


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
