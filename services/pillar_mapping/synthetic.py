"""Synthetic rack halls and downward fisheye frames of them, for tests, benchmarks and demos.

A region is a block of parallel rack rows: a single rack at each end and back-to-back double
racks between, with an aisle between facing racks. Each rack has a front (aisle-facing) and a
back row of uprights ``rack_depth_m`` apart; each pair of consecutive front uprights with the
back ones behind bounds one pallet cell.
"""

from __future__ import annotations

import itertools
from typing import NamedTuple

import numpy as np
import numpy.typing as npt

from services.pillar_mapping.camera import FisheyeCamera, pixel_rays

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]


class HallLayout(NamedTuple):
    """Ground truth of a synthetic hall.

    ``uprights`` (N, 2) metres; ``row_of`` (N,) row index; per row (R,): ``row_start`` (R, 2),
    ``row_theta`` radians, ``row_n``, ``row_d`` metres, ``row_front`` whether the row faces an
    aisle; ``bin_centres`` (B, 2) metres; ``aisles`` (A, 2, 2) aisle centre-line end points.
    """

    uprights: FloatArray
    row_of: IntArray
    row_start: FloatArray
    row_theta: FloatArray
    row_n: IntArray
    row_d: FloatArray
    row_front: npt.NDArray[np.bool_]
    bin_centres: FloatArray
    aisles: FloatArray


def rack_region(
    *,
    origin_xy_m: tuple[float, float] = (0.0, 0.0),
    theta_rad: float = 0.0,
    aisles: int = 3,
    bays: int = 10,
    bay_pitch_m: float = 2.7,
    rack_depth_m: float = 1.1,
    flue_m: float = 0.3,
    aisle_width_m: float = 3.2,
    cross_aisle_every: int = 0,
    cross_aisle_width_m: float = 3.0,
) -> HallLayout:
    """One block of racks whose rows run along ``theta_rad`` from ``origin_xy_m``, stacked to its left.

    With ``cross_aisle_every`` > 0 a cross aisle ``cross_aisle_width_m`` wide (between the uprights either
    side) cuts every row after each ``cross_aisle_every`` bays; each piece of a row is a row of its own.
    """
    u = np.array([np.cos(theta_rad), np.sin(theta_rad)])
    v = np.array([-np.sin(theta_rad), np.cos(theta_rad)])
    offsets: list[tuple[float, bool, int]] = []  # (offset along v, is front, direction to back)
    w = 0.0
    offsets += [(w, False, 0), (w + rack_depth_m, True, -1)]
    w += rack_depth_m
    for _ in range(aisles - 1):
        w += aisle_width_m
        offsets += [(w, True, 1), (w + rack_depth_m, False, 0)]
        w += rack_depth_m + flue_m
        offsets += [(w, False, 0), (w + rack_depth_m, True, -1)]
        w += rack_depth_m
    w += aisle_width_m
    offsets += [(w, True, 1), (w + rack_depth_m, False, 0)]
    origin = np.asarray(origin_xy_m, dtype=np.float64)
    every = cross_aisle_every or bays
    block_m = every * bay_pitch_m + cross_aisle_width_m
    pieces = [(k * block_m, min(every, bays - k * every)) for k in range(-(-bays // every))]
    length = pieces[-1][0] + pieces[-1][1] * bay_pitch_m
    uprights, row_of, starts, bins, fronts = [], [], [], [], []
    for off, front, back in offsets:
        for start_m, piece_bays in pieces:
            along = start_m + np.arange(piece_bays + 1) * bay_pitch_m
            start = origin + off * v + start_m * u
            starts.append(start)
            fronts.append(front)
            uprights.append(origin + off * v + along[:, None] * u)
            row_of.append(np.full(piece_bays + 1, len(starts) - 1))
            if back:
                mids = origin + off * v + (along[:-1, None] + 0.5 * bay_pitch_m) * u
                bins.append(mids + back * 0.5 * rack_depth_m * v)
    first_aisle = origin + (rack_depth_m + 0.5 * aisle_width_m) * v
    aisle_lines = [
        [
            first_aisle + k * (aisle_width_m + 2 * rack_depth_m + flue_m) * v,
            first_aisle + k * (aisle_width_m + 2 * rack_depth_m + flue_m) * v + length * u,
        ]
        for k in range(aisles)
    ]
    rows = len(starts)
    return HallLayout(
        uprights=np.concatenate(uprights),
        row_of=np.concatenate(row_of).astype(np.int64),
        row_start=np.asarray(starts),
        row_theta=np.full(rows, theta_rad),
        row_n=np.array([len(r) for r in row_of], dtype=np.int64),
        row_d=np.full(rows, bay_pitch_m),
        row_front=np.array(fronts),
        bin_centres=np.concatenate(bins),
        aisles=np.asarray(aisle_lines, dtype=np.float64),
    )


def merge_layouts(*layouts: HallLayout) -> HallLayout:
    """One hall of several regions."""
    row_base = np.cumsum([0] + [len(lay.row_n) for lay in layouts[:-1]])
    return HallLayout(
        uprights=np.concatenate([lay.uprights for lay in layouts]),
        row_of=np.concatenate([lay.row_of + b for lay, b in zip(layouts, row_base, strict=True)]),
        row_start=np.concatenate([lay.row_start for lay in layouts]),
        row_theta=np.concatenate([lay.row_theta for lay in layouts]),
        row_n=np.concatenate([lay.row_n for lay in layouts]),
        row_d=np.concatenate([lay.row_d for lay in layouts]),
        row_front=np.concatenate([lay.row_front for lay in layouts]),
        bin_centres=np.concatenate([lay.bin_centres for lay in layouts]),
        aisles=np.concatenate([lay.aisles for lay in layouts]),
    )


def noisy_landmarks(
    layout: HallLayout, rng: np.random.Generator, *, sigma_m: float = 0.03, missing_fraction: float = 0.1
) -> tuple[FloatArray, npt.NDArray[np.bool_]]:
    """Landmark table (K, 5) ``x, y, sxx, sxy, syy`` of a random subset of uprights with Gaussian noise.

    Returns the table and the (N,) mask of uprights kept.
    """
    kept = rng.random(len(layout.uprights)) >= missing_fraction
    xy = layout.uprights[kept] + rng.normal(0.0, sigma_m, (int(kept.sum()), 2))
    cov = np.tile([sigma_m**2, 0.0, sigma_m**2], (len(xy), 1))
    return np.hstack([xy, cov]), kept


class Box(NamedTuple):
    """An oriented box: centre (x, y, z) and half sizes in metres, yaw in radians, BGR colour."""

    centre: tuple[float, float, float]
    half: tuple[float, float, float]
    yaw_rad: float
    bgr: tuple[int, int, int]


class Scene(NamedTuple):
    """What the renderer draws: upright cylinders plus boxes (beams, pallets)."""

    uprights: FloatArray
    upright_radius_m: float
    upright_height_m: float
    boxes: tuple[Box, ...]
    upright_bgr: tuple[int, int, int] = (170, 80, 20)


def rack_scene(
    layout: HallLayout,
    rng: np.random.Generator,
    *,
    upright_radius_m: float = 0.05,
    upright_height_m: float = 6.0,
    beam_levels_m: tuple[float, ...] = (1.6, 3.2),
    pallet_fraction: float = 0.5,
) -> Scene:
    """Uprights, orange beams between consecutive uprights of each row, and brown pallets in some cells."""
    boxes: list[Box] = []
    for r in range(len(layout.row_n)):
        pts = layout.uprights[layout.row_of == r]
        yaw = float(layout.row_theta[r])
        for a, b in itertools.pairwise(pts):
            mid = 0.5 * (a + b)
            half_len = 0.5 * float(np.hypot(*(b - a))) - upright_radius_m
            for z in beam_levels_m:
                boxes.append(Box((mid[0], mid[1], z), (half_len, 0.04, 0.06), yaw, (20, 110, 235)))
    for c in layout.bin_centres[rng.random(len(layout.bin_centres)) < pallet_fraction]:
        yaw = float(layout.row_theta[0])
        boxes.append(Box((c[0], c[1], 0.6), (0.55, 0.45, 0.6), yaw, (60, 95, 140)))
    return Scene(layout.uprights, upright_radius_m, upright_height_m, tuple(boxes))


def _floor_colour(x: FloatArray, y: FloatArray) -> FloatArray:
    grain = 0.5 + 0.25 * np.sin(3.1 * x + 1.7 * np.sin(0.9 * y)) * np.sin(2.3 * y + 1.1 * np.sin(1.3 * x))
    grey = 105.0 + 35.0 * grain
    return np.stack([grey, grey, grey * 1.02], axis=-1)


def _sector(order: IntArray, sorted_az: FloatArray, centre: float, spread: float) -> IntArray:
    """Indices of rays whose azimuth lies within ``spread`` of ``centre`` (radians), across the wrap."""
    if spread >= np.pi:
        return order
    lo, hi = centre - spread, centre + spread
    parts = [(lo, hi)]
    if lo < -np.pi:
        parts = [(-np.pi, hi), (lo + 2 * np.pi, np.pi)]
    elif hi > np.pi:
        parts = [(lo, np.pi), (-np.pi, hi - 2 * np.pi)]
    return np.concatenate([order[np.searchsorted(sorted_az, a) : np.searchsorted(sorted_az, b)] for a, b in parts])


def render_fisheye(
    camera: FisheyeCamera,
    scene: Scene,
    pose_xy_yaw: tuple[float, float, float],
    rng: np.random.Generator,
    *,
    camera_height_m: float = 2.5,
    view_radius_m: float = 14.0,
    noise_grey: float = 4.0,
) -> tuple[npt.NDArray[np.uint8], IntArray]:
    """Ray-cast a downward fisheye frame.

    The camera looks straight down from ``camera_height_m`` above the vehicle at
    ``pose_xy_yaw``; the image's up direction (-v) is the vehicle's +x and its right (+u) the
    vehicle's -y, i.e. optical (x, y, z) = vehicle (-y, -x, -z).

    Returns
    -------
    image : ndarray of uint8, shape (H, W, 3)
        BGR frame, black outside the field of view.
    upright_ids : ndarray of int64, shape (H, W)
        Index of the upright seen at each pixel, -1 elsewhere.
    """
    vv, uu = np.mgrid[0 : camera.height, 0 : camera.width]
    rays = pixel_rays(camera, uu.ravel() + 0.0, vv.ravel() + 0.0)
    theta = np.arccos(np.clip(rays[:, 2], -1.0, 1.0))
    inside = theta <= 0.5 * camera.fov_rad
    x, y, yaw = pose_xy_yaw
    c, s = np.cos(yaw), np.sin(yaw)
    bx, by, bz = -rays[inside, 1], -rays[inside, 0], -rays[inside, 2]
    d = np.stack([c * bx - s * by, s * bx + c * by, bz], axis=1)
    o = np.array([x, y, camera_height_m])
    light = np.array([0.3, 0.5, 0.81])
    depth = np.full(len(d), np.inf)
    colour = np.zeros((len(d), 3))
    ids = np.full(len(d), -1, dtype=np.int64)
    down = d[:, 2] < -1e-9
    t_floor = np.where(down, -o[2] / np.where(down, d[:, 2], -1.0), np.inf)
    depth = t_floor
    hit = np.isfinite(t_floor)
    colour[hit] = _floor_colour(o[0] + t_floor[hit] * d[hit, 0], o[1] + t_floor[hit] * d[hit, 1])
    azimuth = np.arctan2(d[:, 1], d[:, 0])
    order = np.argsort(azimuth)
    sorted_az = azimuth[order]
    rad = scene.upright_radius_m
    for i in np.flatnonzero(np.hypot(*(scene.uprights - o[:2]).T) < view_radius_m):
        cx, cy = scene.uprights[i] - o[:2]
        rho = float(np.hypot(cx, cy))
        spread = np.arcsin(min(rad / rho, 1.0)) + 1e-3 if rho > rad else np.pi
        px = _sector(order, sorted_az, float(np.arctan2(cy, cx)), spread)
        dx, dy, dz = d[px, 0], d[px, 1], d[px, 2]
        a = dx * dx + dy * dy
        b = -2 * (dx * cx + dy * cy)
        disc = b * b - 4 * a * (cx * cx + cy * cy - rad * rad)
        ok = (disc >= 0) & (a > 1e-12)
        t = np.where(ok, (-b - np.sqrt(np.where(ok, disc, 0.0))) / (2 * np.where(a > 1e-12, a, 1.0)), np.inf)
        z = o[2] + t * dz
        closer = ok & (t > 0) & (z >= 0) & (z <= scene.upright_height_m) & (t < depth[px])
        if not closer.any():
            continue
        sel = px[closer]
        nx = (t[closer] * dx[closer] - cx) / rad
        ny = (t[closer] * dy[closer] - cy) / rad
        shade = 0.55 + 0.45 * np.clip(nx * light[0] + ny * light[1], 0, 1)
        depth[sel] = t[closer]
        colour[sel] = np.asarray(scene.upright_bgr)[None, :] * shade[:, None]
        ids[sel] = i
    for box in scene.boxes:
        rel = o - np.asarray(box.centre)
        if np.hypot(rel[0], rel[1]) > view_radius_m + box.half[0]:
            continue
        cb, sb = np.cos(box.yaw_rad), np.sin(box.yaw_rad)
        ol = np.array([cb * rel[0] + sb * rel[1], -sb * rel[0] + cb * rel[1], rel[2]])
        half = np.asarray(box.half)
        if abs(ol[0]) <= half[0] and abs(ol[1]) <= half[1]:
            px = np.arange(len(d))
        else:
            corners = np.array([[sx * half[0], sy * half[1]] for sx in (-1, 1) for sy in (-1, 1)])
            world = np.asarray(box.centre[:2]) + corners @ np.array([[cb, sb], [-sb, cb]]) - o[:2]
            angles = np.arctan2(world[:, 1], world[:, 0])
            mid = float(np.arctan2(-rel[1], -rel[0]))
            dev = (angles - mid + np.pi) % (2 * np.pi) - np.pi
            px = _sector(order, sorted_az, mid, float(np.abs(dev).max()) + 1e-3)
        dsel = d[px]
        dl = np.stack([cb * dsel[:, 0] + sb * dsel[:, 1], -sb * dsel[:, 0] + cb * dsel[:, 1], dsel[:, 2]], axis=1)
        with np.errstate(divide="ignore", invalid="ignore"):
            t1 = (-half - ol) / dl
            t2 = (half - ol) / dl
        tmin_axes = np.nan_to_num(np.minimum(t1, t2), nan=-np.inf)
        tmax = np.nan_to_num(np.maximum(t1, t2), nan=np.inf).min(axis=1)
        tmin = tmin_axes.max(axis=1)
        closer = (tmax >= tmin) & (tmin > 0) & (tmin < depth[px])
        if not closer.any():
            continue
        sel = px[closer]
        axis = np.argmax(tmin_axes[closer], axis=1)
        shade = np.where(axis == 2, 1.0, 0.7)
        depth[sel] = tmin[closer]
        colour[sel] = np.asarray(box.bgr)[None, :] * shade[:, None]
        ids[sel] = -1
    image = np.zeros((camera.height * camera.width, 3))
    image[inside] = colour + rng.normal(0.0, noise_grey, colour.shape)
    id_image = np.full(camera.height * camera.width, -1, dtype=np.int64)
    id_image[inside] = ids
    shape = (camera.height, camera.width)
    return np.clip(image, 0, 255).astype(np.uint8).reshape(*shape, 3), id_image.reshape(shape)


def default_camera(*, size_px: int = 640, fov_rad: float = float(np.deg2rad(185.0))) -> FisheyeCamera:
    """A square equidistant fisheye whose image circle of ``fov_rad`` just fits the image."""
    f = 0.5 * size_px / (0.5 * fov_rad)
    k = np.array([[f, 0.0, 0.5 * size_px - 0.5], [0.0, f, 0.5 * size_px - 0.5], [0.0, 0.0, 1.0]])
    return FisheyeCamera(k, np.zeros(4), size_px, size_px, fov_rad)
