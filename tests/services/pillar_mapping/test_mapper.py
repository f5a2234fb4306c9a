import numpy as np
import pytest

from services.pillar_mapping import BearingOnlyMapper, PillarMappingError, triangulate_bearings
from services.pillar_mapping.evaluation import drive_aisles, map_rmse, simulated_bearings
from services.pillar_mapping.synthetic import rack_region


def test_triangulate_bearings_recovers_a_point_from_two_rays() -> None:
    origins = np.array([[0.0, 0.0], [2.0, 0.0]])
    target = np.array([1.0, 3.0])
    angles = np.arctan2(target[1] - origins[:, 1], target[0] - origins[:, 0])
    tri = triangulate_bearings(origins, angles, np.full(2, 1e-3))
    assert np.allclose(tri.mean, target, atol=1e-9)
    assert np.all(np.linalg.eigvalsh(tri.cov) > 0)
    assert tri.parallax_rad > np.deg2rad(30)


def test_triangulate_bearings_refuses_parallel_rays() -> None:
    with pytest.raises(PillarMappingError, match="parallel"):
        triangulate_bearings(np.array([[0.0, 0.0], [1.0, 0.0]]), np.zeros(2), np.full(2, 1e-3))


def test_mapper_maps_every_upright_within_five_centimetres_after_one_pass_per_aisle() -> None:
    rng = np.random.default_rng(11)
    layout = rack_region(aisles=2, bays=8)
    mapper = BearingOnlyMapper()
    # the detector's bearing errors on rendered frames are ~0.02 deg median; 0.1 deg is pessimistic
    for pose in drive_aisles(layout, 0.25):
        bearings = simulated_bearings(layout.uprights, pose, rng, sigma_rad=np.deg2rad(0.1))
        mapper.observe(pose, bearings, np.full(bearings.size, np.deg2rad(0.1)))
    landmarks = mapper.reliable_landmarks()
    rmse, matched, extra = map_rmse(landmarks.means, layout.uprights)
    assert matched == len(layout.uprights)
    assert extra == 0
    assert rmse <= 0.05
    assert np.all(np.linalg.eigvalsh(landmarks.covs) > 0)


def test_mapper_stays_empty_when_bearings_never_agree() -> None:
    rng = np.random.default_rng(3)
    mapper = BearingOnlyMapper()
    for k in range(60):
        clutter = rng.uniform(-np.pi, np.pi, 5)
        mapper.observe((0.2 * k, 0.0, 0.0), clutter, np.full(5, np.deg2rad(0.1)))
    assert len(mapper.reliable_landmarks().means) == 0


def test_mapper_rejects_a_non_finite_pose() -> None:
    with pytest.raises(PillarMappingError, match="sensor pose"):
        BearingOnlyMapper().observe((np.nan, 0.0, 0.0), [0.1], [0.01])
