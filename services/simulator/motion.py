"""Driving a route: a unicycle robot following waypoints by pure pursuit, and its drifting odometry."""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from services.simulator.errors import SimulatorError
from services.simulator.world import FloatArray

_STEP_M = 0.05


class Trajectory(NamedTuple):
    """Poses and velocities at a fixed rate: ``t_s`` (n,) seconds from the start; ``pose`` (n, 3)
    x, y in metres and yaw in radians; ``twist`` (n, 2) forward speed m/s and turn rate rad/s."""

    t_s: FloatArray
    pose: FloatArray
    twist: FloatArray


def _wrap(angle: FloatArray | float) -> FloatArray:
    return np.asarray((np.asarray(angle) + math.pi) % (2 * math.pi) - math.pi, dtype=np.float64)


def drive(waypoints: FloatArray, *, rate_hz: float = 20.0, speed_mps: float = 1.2,
          max_turn_rate_rad_s: float = 0.8, accel_mps2: float = 0.5, lookahead_m: float = 0.8,
          max_duration_s: float = 36_000.0) -> Trajectory:
    """Follow ``waypoints`` (k, 2) by pure pursuit at ``rate_hz``, from the first point to the last.

    The robot starts at rest facing the second waypoint, turns on the spot when the path bends
    by more than about 60 degrees, and respects ``speed_mps``, ``max_turn_rate_rad_s`` and
    ``accel_mps2``.
    """
    points = np.asarray(waypoints, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] != 2 or len(points) < 2:
        raise SimulatorError(f"need at least two waypoints (k, 2), got shape {points.shape}")
    if not (rate_hz > 0 and speed_mps > 0 and max_turn_rate_rad_s > 0 and accel_mps2 > 0 and lookahead_m > 0):
        raise SimulatorError("rate, speed, turn rate, acceleration and lookahead must be positive")
    seg = np.diff(points, axis=0)
    lengths = np.hypot(*seg.T)
    cumulative = np.concatenate([[0.0], np.cumsum(lengths)])
    samples = np.arange(0.0, cumulative[-1], _STEP_M)
    path = np.column_stack([np.interp(samples, cumulative, points[:, 0]), np.interp(samples, cumulative, points[:, 1])])
    path = np.vstack([path, points[-1]])
    dt = 1.0 / rate_hz
    ahead = max(1, round(lookahead_m / _STEP_M))
    x, y = points[0]
    first = path[min(ahead, len(path) - 1)] - points[0]
    yaw = math.atan2(first[1], first[0])
    v = 0.0
    k = 0
    poses, twists = [], []
    for _ in range(round(max_duration_s * rate_hz)):
        window = path[k:k + 4 * ahead]
        k += int(np.argmin(np.hypot(window[:, 0] - x, window[:, 1] - y)))
        if k >= len(path) - 1 and math.hypot(path[-1, 0] - x, path[-1, 1] - y) < 0.1:
            break
        tx, ty = path[min(k + ahead, len(path) - 1)]
        alpha = float(_wrap(math.atan2(ty - y, tx - x) - yaw))
        distance = math.hypot(tx - x, ty - y)
        if abs(alpha) > 1.0:
            v_cmd, w = 0.0, math.copysign(max_turn_rate_rad_s, alpha)
        else:
            v_cmd = min(speed_mps, math.sqrt(2 * accel_mps2 * max(distance, 0.0)) + 0.05,
                        speed_mps * max(0.2, math.cos(alpha)))
            w = v_cmd * 2.0 * math.sin(alpha) / max(distance, 1e-3)
            if abs(w) > max_turn_rate_rad_s:
                v_cmd *= max_turn_rate_rad_s / abs(w)
                w = math.copysign(max_turn_rate_rad_s, w)
        v = min(v_cmd, v + accel_mps2 * dt) if v_cmd > v else max(v_cmd, v - 2 * accel_mps2 * dt)
        poses.append((x, y, yaw))
        twists.append((v, w))
        x += v * dt * math.cos(yaw + 0.5 * w * dt)
        y += v * dt * math.sin(yaw + 0.5 * w * dt)
        yaw = float(_wrap(yaw + w * dt))
    else:
        raise SimulatorError(f"route not finished within {max_duration_s} s")
    poses.append((x, y, yaw))
    twists.append((0.0, 0.0))
    n = len(poses)
    return Trajectory(np.arange(n, dtype=np.float64) * dt, np.array(poses, np.float64), np.array(twists, np.float64))


def drifting_odometry(trajectory: Trajectory, rng: np.random.Generator, *, scale_std: float = 0.01,
                      gyro_bias_std_rad_s: float = 0.002, speed_noise_mps: float = 0.01,
                      turn_noise_rad_s: float = 0.005) -> FloatArray:
    """Wheel odometry (n, 3) in the odom frame: the true motion integrated with a constant scale
    error, a gyro bias and white noise, starting at the origin. Drift grows without bound."""
    dt = np.diff(trajectory.t_s, prepend=trajectory.t_s[0])
    scale = 1.0 + rng.normal(0.0, scale_std)
    bias = rng.normal(0.0, gyro_bias_std_rad_s)
    n = len(dt)
    v = trajectory.twist[:, 0] * scale + rng.normal(0.0, speed_noise_mps, n) * (trajectory.twist[:, 0] != 0)
    w = trajectory.twist[:, 1] + (bias + rng.normal(0.0, turn_noise_rad_s, n)) * (trajectory.twist[:, 0] != 0)
    # increments applied between consecutive samples use the previous sample's velocity
    v_prev, w_prev = np.roll(v, 1), np.roll(w, 1)
    v_prev[0] = w_prev[0] = 0.0
    yaw = np.cumsum(w_prev * dt)
    mid = yaw - 0.5 * w_prev * dt
    x = np.cumsum(v_prev * dt * np.cos(mid))
    y = np.cumsum(v_prev * dt * np.sin(mid))
    return np.column_stack([x, y, _wrap(yaw)])


def compose_se2(a: FloatArray, b: FloatArray) -> FloatArray:
    """Poses (n, 3) ``a ∘ b``: ``b`` expressed in ``a``'s frame, mapped out of it."""
    c, s = np.cos(a[:, 2]), np.sin(a[:, 2])
    return np.column_stack([a[:, 0] + c * b[:, 0] - s * b[:, 1], a[:, 1] + s * b[:, 0] + c * b[:, 1],
                            _wrap(a[:, 2] + b[:, 2])])


def invert_se2(a: FloatArray) -> FloatArray:
    """Inverse poses (n, 3)."""
    c, s = np.cos(a[:, 2]), np.sin(a[:, 2])
    return np.column_stack([-c * a[:, 0] - s * a[:, 1], s * a[:, 0] - c * a[:, 1], _wrap(-a[:, 2])])


def localisation_correction(true_pose: FloatArray, odom_pose: FloatArray, rng: np.random.Generator, *,
                            position_noise_m: float = 0.01, yaw_noise_rad: float = 0.002) -> FloatArray:
    """map->odom (n, 3) a localiser would publish: it makes odom->base_link land on the true pose, up
    to a small localisation error, so map-frame poses are right however far odometry drifts."""
    n = len(true_pose)
    estimate = true_pose + np.column_stack([rng.normal(0.0, position_noise_m, (n, 2)),
                                            rng.normal(0.0, yaw_noise_rad, n)])
    return compose_se2(estimate, invert_se2(odom_pose))
