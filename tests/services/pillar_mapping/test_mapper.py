import numpy as np
import pytest

from services.pillar_mapping import BearingOnlyMapper, PillarMappingError, triangulate_bearings
from services.pillar_mapping.evaluation import drive_aisles, map_rmse, simulated_bearings
from services.pillar_mapping.mapper import bearing_model
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


def test_bearing_model_jacobians_match_finite_differences() -> None:
    # the vehicle Jacobian is what estimating the vehicle as well (SLAM) needs; the landmark one the EKF uses
    pose = np.array([1.0, -2.0, 0.3])
    landmarks = np.array([[4.0, 1.0], [-3.0, 0.5], [1.5, -6.0]])
    predicted, h_vehicle, h_landmark = bearing_model(pose, landmarks)
    step = 1e-6
    for k in range(3):
        moved = pose + step * np.eye(3)[k]
        assert np.allclose((bearing_model(moved, landmarks)[0] - predicted) / step, h_vehicle[:, k], atol=1e-5)
    for k in range(2):
        moved = landmarks + step * np.eye(2)[k]
        assert np.allclose((bearing_model(pose, moved)[0] - predicted) / step, h_landmark[:, k], atol=1e-5)


def test_mapping_with_a_slightly_wrong_localisation_stays_within_five_centimetres() -> None:
    rng = np.random.default_rng(12)
    layout = rack_region(aisles=2, bays=8)
    sigma = np.deg2rad(0.05)
    pose_sigma = np.array([0.01, 0.01, np.deg2rad(0.2)])
    mapper = BearingOnlyMapper()
    error = rng.normal(0.0, 1.0, 3) * pose_sigma
    for pose in drive_aisles(layout, 0.25):
        error = 0.9 * error + np.sqrt(1 - 0.9**2) * rng.normal(0.0, 1.0, 3) * pose_sigma  # slowly varying
        bearings = simulated_bearings(layout.uprights, pose, rng, sigma_rad=sigma)
        mapper.observe(tuple(np.asarray(pose) + error), bearings, np.full(bearings.size, sigma),
                       pose_cov=np.diag(pose_sigma**2))
    rmse, matched, extra = map_rmse(mapper.reliable_landmarks().means, layout.uprights)
    assert matched >= 0.95 * len(layout.uprights)
    assert extra == 0
    assert rmse <= 0.05


def test_mapper_rejects_a_malformed_pose_covariance() -> None:
    with pytest.raises(PillarMappingError, match="pose_cov"):
        BearingOnlyMapper().observe((0.0, 0.0, 0.0), [0.1], [0.01], pose_cov=-np.eye(3))


def test_uprights_hidden_on_later_passes_stay_mapped() -> None:
    # the live demo lost cells on its second round: uprights seen well on the first pass, then in
    # range but hidden behind the racks on every later pass, fell below the hit ratio and out of the map
    rng = np.random.default_rng(5)
    layout = rack_region(aisles=2, bays=8)
    sigma = np.deg2rad(0.1)
    mapper = BearingOnlyMapper()
    poses = drive_aisles(layout, 0.25)
    for pose in poses:
        bearings = simulated_bearings(layout.uprights, pose, rng, sigma_rad=sigma)
        mapper.observe(pose, bearings, np.full(bearings.size, sigma))
    first = mapper.reliable_landmarks().means
    hidden = layout.row_of == 0
    assert map_rmse(first, layout.uprights[hidden])[1] == hidden.sum()
    for _ in range(4):
        for pose in poses:
            bearings = simulated_bearings(layout.uprights[~hidden], pose, rng, sigma_rad=sigma)
            mapper.observe(pose, bearings, np.full(bearings.size, sigma))
    rmse, matched, _ = map_rmse(mapper.reliable_landmarks().means, layout.uprights)
    assert matched == len(layout.uprights)
    assert rmse <= 0.05


def test_a_ghost_matched_in_few_frames_of_its_pass_does_not_stay_in_the_map() -> None:
    mapper = BearingOnlyMapper()
    rng = np.random.default_rng(8)
    ghost = np.array([[3.0, 2.0]])
    sigma = np.deg2rad(0.1)
    for k in range(80):
        pose = (0.25 * k - 5.0, 0.0, 0.0)
        seen = ghost if k < 12 else np.zeros((0, 2))  # seen at first, then no longer from where rays crossed
        bearings = simulated_bearings(seen, pose, rng, sigma_rad=sigma, miss_rate=0.0, clutter_rate=0.0)
        mapper.observe(pose, bearings, np.full(bearings.size, sigma))
    for k in range(60):  # far away: the pass ends
        mapper.observe((100.0 + k, 0.0, 0.0), np.zeros(0), np.zeros(0))
    assert len(mapper.reliable_landmarks().means) == 0
