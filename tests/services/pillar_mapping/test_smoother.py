import numpy as np
import pytest

from services.pillar_mapping import BearingOnlyMapper, PillarMappingError
from services.pillar_mapping.evaluation import drive_aisles, map_rmse, simulated_bearings
from services.pillar_mapping.smoother import BearingLog, FrameLog, OdometryNoise, odometry_steps, smooth_map
from services.pillar_mapping.synthetic import rack_region

SIGMA = np.deg2rad(0.1)
POSE_SIGMA = np.array([0.03, 0.03, np.deg2rad(0.5)])


def _odometry(poses: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Wheel odometry along ``poses``: 1 % scale error, a heading bias per metre, a little white noise."""
    c, s = np.cos(poses[:-1, 2]), np.sin(poses[:-1, 2])
    d = np.diff(poses[:, :2], axis=0)
    steps = np.column_stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1], np.diff(poses[:, 2])])
    steps[:, :2] *= 1.0 + rng.normal(0.0, 0.01)
    steps[:, 2] += rng.normal(0.0, 0.002) * np.hypot(steps[:, 0], steps[:, 1]) + rng.normal(0.0, 5e-4, len(steps))
    out = np.zeros_like(poses)
    for k, (dx, dy, dyaw) in enumerate(steps):
        ck, sk = np.cos(out[k, 2]), np.sin(out[k, 2])
        out[k + 1] = (out[k, 0] + ck * dx - sk * dy, out[k, 1] + sk * dx + ck * dy, out[k, 2] + dyaw)
    return out


def _survey(smooth_every: int, *, reset_at: int | None = None) -> tuple[float, float]:
    """(RMSE of the EKF map, RMSE after smoothing) under a slowly varying 3 cm / 0.5 deg localisation error."""
    rng = np.random.default_rng(4)
    layout = rack_region(aisles=2, bays=8)
    poses = np.array(drive_aisles(layout, 0.25))
    odometry = _odometry(poses, rng)
    if reset_at is not None:
        odometry[reset_at:] -= odometry[reset_at]  # the odometry frame restarts at the origin
    errors = np.zeros_like(poses)
    error = rng.normal(0.0, 1.0, 3) * POSE_SIGMA
    for k in range(len(poses)):
        error = 0.9 * error + np.sqrt(1 - 0.9**2) * rng.normal(0.0, 1.0, 3) * POSE_SIGMA
        errors[k] = error
    frames = []
    for pose in poses:
        bearings = simulated_bearings(layout.uprights, tuple(pose), rng, sigma_rad=SIGMA)
        frames.append(bearings)
    results = []
    for smoothed in (False, True):
        mapper = BearingOnlyMapper()
        for k, bearings in enumerate(frames, start=1):
            mapper.observe(tuple(poses[k - 1] + errors[k - 1]), bearings, np.full(bearings.size, SIGMA),
                           pose_cov=np.diag(POSE_SIGMA**2), odometry_pose=tuple(odometry[k - 1]))
            if smoothed and (k % smooth_every == 0 or k == len(frames)):
                mapper.smooth()
        rmse, matched, _ = map_rmse(mapper.reliable_landmarks().means, layout.uprights)
        assert matched >= 0.9 * len(layout.uprights)
        results.append(rmse)
    return results[0], results[1]


def test_smoothing_with_odometry_averages_out_a_slowly_varying_localisation_error() -> None:
    ekf, smoothed = _survey(48)
    assert smoothed < ekf
    assert smoothed <= 0.05


def test_an_odometry_reset_is_left_out_rather_than_trusted() -> None:
    ekf, smoothed = _survey(48, reset_at=150)
    assert smoothed < ekf
    assert smoothed <= 0.05


def test_odometry_links_only_consecutive_frames_of_one_robot_and_drops_a_reset() -> None:
    poses = np.column_stack([np.arange(8.0), np.zeros(8), np.zeros(8)])
    odometry = poses.copy()
    odometry[6] += [5.0, 0.0, 0.0]  # robot 0's odometry jumps between its frames 4 and 6
    frames = FrameLog(poses, np.tile(np.diag([1e-4, 1e-4, 1e-4]), (8, 1, 1)), odometry,
                      np.array([0, 1, 0, 1, 0, 1, 0, 1]))
    first, steps, _, rejected = odometry_steps(frames, OdometryNoise())
    assert rejected == 1
    assert sorted(first.tolist()) == [0, 1, 2, 3, 5]  # 4 -> 6 left out; 0 -> 2 -> 4, 1 -> 3 -> 5 -> 7 kept
    assert np.allclose(steps[:, 0], 2.0)


def test_smoothing_an_empty_map_does_nothing() -> None:
    assert BearingOnlyMapper().smooth() is None


def test_inconsistent_logs_and_odometry_are_refused() -> None:
    frames = FrameLog(np.zeros((2, 3)), np.zeros((1, 3, 3)), np.zeros((2, 3)), np.zeros(2, dtype=np.int64))
    bearings = BearingLog(np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64), np.zeros(0), np.zeros(0))
    with pytest.raises(PillarMappingError, match="one entry per frame"):
        smooth_map(frames, bearings, np.zeros((0, 2)))
    with pytest.raises(PillarMappingError, match="odometry pose"):
        BearingOnlyMapper().observe((0.0, 0.0, 0.0), [0.1], [0.01], odometry_pose=(np.nan, 0.0, 0.0))


def _flue_survey(reassociate: bool) -> tuple[np.ndarray, np.ndarray]:
    """(reliable landmarks, true uprights) of racks with a 0.2 m flue surveyed under a slowly varying
    3 cm / 0.5 deg localisation error, smoothed every 48 frames."""
    rng = np.random.default_rng(0)
    layout = rack_region(aisles=2, bays=6, flue_m=0.2)
    poses = np.array(drive_aisles(layout, 0.25))
    odometry = _odometry(poses, rng)
    error = rng.normal(0.0, 1.0, 3) * POSE_SIGMA
    mapper = BearingOnlyMapper(reassociate=reassociate)
    for k, pose in enumerate(poses, start=1):
        error = 0.9 * error + np.sqrt(1 - 0.9**2) * rng.normal(0.0, 1.0, 3) * POSE_SIGMA
        bearings = simulated_bearings(layout.uprights, tuple(pose), rng, sigma_rad=SIGMA)
        mapper.observe(tuple(pose + error), bearings, np.full(bearings.size, SIGMA),
                       pose_cov=np.diag(POSE_SIGMA**2), odometry_pose=tuple(odometry[k - 1]))
        if k % 48 == 0 or k == len(poses):
            mapper.smooth()
    return mapper.reliable_landmarks().means, layout.uprights


def test_re_association_after_smoothing_maps_the_uprights_either_side_of_a_flue_as_two() -> None:
    raw, uprights = _flue_survey(reassociate=False)
    mapped, _ = _flue_survey(reassociate=True)
    own_raw = map_rmse(raw, uprights, gate_m=0.1)[1]  # uprights with a landmark of their own within 10 cm
    own = map_rmse(mapped, uprights, gate_m=0.1)[1]
    assert own > own_raw
    assert own >= 0.95 * len(uprights)
