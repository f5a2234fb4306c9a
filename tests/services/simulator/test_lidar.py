"""Lidar: exact ray casting, and every simulated return lies on a true surface within the noise."""

from __future__ import annotations

import math

import numpy as np

from services.simulator import LidarModel, Segments, cast_rays, demo_layout, world_from_layout
from services.simulator.actors import dynamic_boxes
from services.simulator.lidar import add_noise
from services.simulator.world import AreaKind, Boxes, ObjectClass


def _box(x: float, y: float, length: float, width: float) -> Boxes:
    return Boxes(np.array([[x, y]]), np.array([[0.0, 1.0]]), np.array([[length, width]]), np.zeros(1),
                 np.array([ObjectClass.UPRIGHT], np.int8), np.zeros((1, 3), np.uint8))


def test_beam_straight_at_a_box_returns_the_distance_to_its_near_face() -> None:
    segments = Segments.from_boxes(_box(5.0, 0.0, 0.2, 0.2), height_m=0.2)
    ranges, labels = cast_rays(np.zeros(2), -0.1, 0.05, 5, [(segments, None)], max_range_m=30.0)
    assert math.isclose(ranges[2], 4.9)
    assert labels[2] == ObjectClass.UPRIGHT
    assert np.isinf(ranges[0]) and labels[0] == -1


def test_box_above_the_scan_plane_is_not_seen() -> None:
    assert len(Segments.from_boxes(_box(5.0, 0.0, 0.2, 0.2), height_m=1.5).starts) == 0


def _distance_to_segments(points: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    ab = b - a
    t = np.clip(np.einsum("pnk,nk->pn", points[:, None] - a[None], ab) / np.maximum((ab**2).sum(1), 1e-12), 0, 1)
    nearest = a[None] + t[..., None] * ab[None]
    distances: np.ndarray = np.linalg.norm(points[:, None] - nearest, axis=2).min(axis=1)
    return distances


def test_cast_matches_brute_force_over_every_edge() -> None:
    world = world_from_layout(demo_layout())
    segments = Segments.from_boxes(world.boxes, height_m=0.2)
    model = LidarModel()
    free = [a.polygon.mean(axis=0) for a in world.areas if a.kind in (AreaKind.CORRIDOR, AreaKind.JUNCTION)]
    for origin in free[::3]:
        ranges, _ = cast_rays(origin, model.angle_min_rad, model.angle_increment_rad, model.beams,
                              [(segments, None)], max_range_m=model.range_max_m)
        bearings = model.angle_min_rad + np.arange(model.beams) * model.angle_increment_rad
        d = np.stack([np.cos(bearings), np.sin(bearings)], axis=1)
        p, e = segments.starts - origin, segments.ends - segments.starts
        denom = d[:, None, 0] * e[None, :, 1] - d[:, None, 1] * e[None, :, 0]
        with np.errstate(divide="ignore", invalid="ignore"):
            t = (p[None, :, 0] * e[None, :, 1] - p[None, :, 1] * e[None, :, 0]) / denom
            u = (p[None, :, 0] * d[:, None, 1] - p[None, :, 1] * d[:, None, 0]) / denom
        hit = (t > 0) & (u >= -1e-9) & (u <= 1 + 1e-9) & (t <= model.range_max_m)
        expected = np.where(hit, t, np.inf).min(axis=1)
        np.testing.assert_allclose(ranges, expected, atol=1e-9)


def test_every_noisy_return_lies_on_a_true_surface_within_the_noise() -> None:
    world = world_from_layout(demo_layout())
    model = LidarModel()
    static = Segments.from_boxes(world.boxes, height_m=model.height_m)
    rng = np.random.default_rng(7)
    free = [a.polygon.mean(axis=0) for a in world.areas if a.kind in (AreaKind.CORRIDOR, AreaKind.JUNCTION)]
    for time_s, origin in zip((0.0, 13.0, 40.0), free[1::4], strict=False):
        dynamic = Segments.from_boxes(dynamic_boxes(world, time_s), height_m=model.height_m)
        yaw = rng.uniform(-math.pi, math.pi)
        ranges, _ = cast_rays(origin, yaw + model.angle_min_rad, model.angle_increment_rad, model.beams,
                              [(static, None), (dynamic, None)], max_range_m=model.range_max_m)
        noisy = add_noise(ranges, model, rng)
        returned = np.isfinite(noisy)
        assert returned.mean() > 0.9
        bearings = yaw + model.angle_min_rad + np.arange(model.beams)[returned] * model.angle_increment_rad
        points = origin + noisy[returned, None] * np.stack([np.cos(bearings), np.sin(bearings)], axis=1)
        a = np.concatenate([static.starts, dynamic.starts])
        b = np.concatenate([static.ends, dynamic.ends])
        assert _distance_to_segments(points, a, b).max() < 5 * model.range_noise_m
