"""Cameras: uprights appear in the fisheye at their predicted bearing; RGB-D depth matches the geometry."""

from __future__ import annotations

import math

import numpy as np

from services.simulator import FisheyeModel, RgbdModel, depth_image_mm, render_boxes, render_fisheye, world_from_layout
from services.simulator.cameras import FISHEYE_MOUNT, RGBD_MOUNT
from services.simulator.render import box_corners
from services.simulator.stream import _planar_matrix
from services.simulator.world import ObjectClass


def _bare_layout() -> dict[str, object]:
    return {"name": "bare", "hall": {"length_m": 30.0, "width_m": 12.0},
            "blocks": [{"id": "A", "origin_m": [3.0, 3.0], "aisles": 1, "bays": 8, "levels": 1, "fill": 0.0,
                        "aisle_width_m": 3.0}]}


def test_every_upright_in_view_appears_at_its_predicted_bearing_in_the_fisheye() -> None:
    world = world_from_layout(_bare_layout())
    model = FisheyeModel()
    aisle_y = 3.0 + 1.1 + 1.5
    pose = np.array([12.3, aisle_y, 0.4])
    optical = _planar_matrix(pose) @ FISHEYE_MOUNT
    rgb, kind = render_fisheye(world.boxes, optical, model)
    centre = 0.5 * (model.size - 1)
    height = optical[2, 3]
    checked = 0
    for xy in world.uprights.xy:
        local = optical[:3, :3].T @ (np.array([xy[0], xy[1], 0.5 * height]) - optical[:3, 3])
        distance = math.hypot(*(xy - optical[:2, 3]))
        if distance > 6.0:
            continue
        bearing = math.atan2(local[1], local[0])
        theta = math.atan2(math.hypot(local[0], local[1]), local[2])
        r = model.focal_px * theta
        u, v = centre + r * math.cos(bearing), centre + r * math.sin(bearing)
        patch = kind[round(v) - 1:round(v) + 2, round(u) - 1:round(u) + 2]
        assert (patch == ObjectClass.UPRIGHT).any(), f"upright at {xy} not at its bearing {math.degrees(bearing):.1f}"
        checked += 1
    assert checked >= 8
    upright = kind == ObjectClass.UPRIGHT
    assert (rgb[upright][:, 2] > rgb[upright][:, 0]).mean() > 0.9  # colour-coded (blue) bars


def _slab_depth(boxes, optical: np.ndarray, rays: np.ndarray) -> np.ndarray:  # type: ignore[no-untyped-def]
    """Reference: optical-axis depth of the first box or floor hit, by ray-box slab tests (axis-aligned boxes)."""
    corners = box_corners(boxes)
    lo, hi = corners.min(axis=1), corners.max(axis=1)
    origin = optical[:3, 3]
    directions = rays @ optical[:3, :3].T
    with np.errstate(divide="ignore", invalid="ignore"):
        t0 = (lo[None] - origin) / directions[:, None]
        t1 = (hi[None] - origin) / directions[:, None]
    near = np.nanmax(np.minimum(t0, t1), axis=2)
    far = np.nanmin(np.maximum(t0, t1), axis=2)
    hit = (near <= far) & (far > 0)
    t = np.where(hit, np.maximum(near, 0), np.inf).min(axis=1)
    floor = np.where(directions[:, 2] < 0, -origin[2] / directions[:, 2], np.inf)
    depth: np.ndarray = np.minimum(t, floor)  # rays have unit optical z, so t is the depth
    return depth


def test_rgbd_depth_matches_the_scene_geometry() -> None:
    layout = _bare_layout()
    layout["blocks"][0].update(levels=3, fill=0.8)  # type: ignore[index]
    world = world_from_layout(layout)
    model = RgbdModel()
    camera = model.camera()
    optical = _planar_matrix(np.array([10.0, 3.0 + 1.1 + 1.5, 0.0])) @ RGBD_MOUNT
    rendered = render_boxes(world.boxes, optical, camera)
    v, u = np.mgrid[0:camera.height:7, 0:camera.width:7]
    rays = np.stack([(u - camera.cx) / camera.fx, (v - camera.cy) / camera.fy, np.ones(u.shape)], axis=-1)
    rays = rays.reshape(-1, 3)
    expected = _slab_depth(world.boxes, optical, rays)
    got = rendered.depth_m[v.ravel(), u.ravel()]
    close = np.abs(got - expected) < 0.01
    assert close.mean() > 0.98  # the rest are pixels on face edges
    depth = depth_image_mm(rendered.depth_m, model, np.random.default_rng(0))
    valid = depth > 0
    assert np.all((rendered.depth_m[valid] >= model.min_range_m) & (rendered.depth_m[valid] <= model.max_range_m))
    z = rendered.depth_m[valid]
    sigma = 0.0012 + 0.0019 * (z - 0.4) ** 2
    assert np.all(np.abs(depth[valid] / 1000.0 - z) < 6 * sigma + 0.0006)
