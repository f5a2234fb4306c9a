"""A synthetic warehouse and annotated-scan runs through it, for tests and benchmarks.

The hall is axis-aligned boxes in the map frame: outer walls with gates in the south wall, floor
pallets along it, and rows of back-to-back racks (uprights every bay, pallets in most bays) with
aisles between them; forklifts and humans move back and forth in aisles. A robot drives one
loop per aisle (up the west cross aisle, along the aisle, back west along the south cross aisle to
its start, so every loop returns to a seen place) and finally down the first aisle again, with a
camera looking forward-left. Each frame casts cones against the boxes; a simulated labeller labels each
object it sees once per frame through a confusion matrix like the article's classifiers (wall and
gate, rack and pallet mixed up), with lower confidence when wrong, plus phantom detections. The
camera pose it reports comes from odometry that drifts.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
import numpy.typing as npt
from scipy.ndimage import distance_transform_edt
from scipy.spatial import cKDTree

from services.semantic_fusion import se2
from services.semantic_fusion.scan import RangeScan, ScanObservation, observation_from_arrays, range_scan_from_arrays
from shared.vocabulary import SemanticClass

CLASS_NAMES = tuple(c.name.lower() for c in SemanticClass if c is not SemanticClass.NONE)
"""The simulated labeller's ``class_names`` (distribution order)."""

_S = SemanticClass
_CONFUSION: dict[SemanticClass, dict[SemanticClass, float]] = {
    _S.WALL: {_S.GATE: 0.6, _S.RACK: 0.2, _S.UNKNOWN: 0.2},
    _S.RACK: {_S.PALLET: 0.6, _S.WALL: 0.2, _S.UNKNOWN: 0.2},
    _S.PALLET: {_S.RACK: 0.6, _S.FORKLIFT: 0.1, _S.UNKNOWN: 0.3},
    _S.GATE: {_S.WALL: 0.8, _S.UNKNOWN: 0.2},
    _S.FORKLIFT: {_S.PALLET: 0.4, _S.HUMAN: 0.2, _S.UNKNOWN: 0.4},
    _S.HUMAN: {_S.FORKLIFT: 0.4, _S.UNKNOWN: 0.6},
}
_ERROR_RATE = {_S.WALL: 0.15, _S.RACK: 0.2, _S.PALLET: 0.15, _S.GATE: 0.25, _S.FORKLIFT: 0.15, _S.HUMAN: 0.15}
_HEIGHT_M = {_S.WALL: 6.0, _S.RACK: 8.0, _S.PALLET: 1.4, _S.GATE: 4.5, _S.FORKLIFT: 2.2, _S.HUMAN: 1.8}


@dataclass(frozen=True, slots=True)
class Warehouse:
    """Static boxes (k, 4) ``[x_min, y_min, x_max, y_max]`` metres with classes, an aisle route and movers.

    ``movers`` (j, 6): ``[x0, y0, x1, y1, speed_mps, phase_s]``, each a box of
    ``mover_sizes`` (j, 2) moving back and forth between the two points; ``mover_classes`` (j,).
    """

    length_m: float
    width_m: float
    boxes: npt.NDArray[np.float64]
    classes: npt.NDArray[np.uint8]
    route: npt.NDArray[np.float64]
    movers: npt.NDArray[np.float64]
    mover_sizes: npt.NDArray[np.float64]
    mover_classes: npt.NDArray[np.uint8]


def make_warehouse(*, length_m: float = 60.0, width_m: float = 30.0, aisle_width_m: float = 3.2,
                   bay_m: float = 2.7, n_forklifts: int = 2, n_humans: int = 3, seed: int = 0) -> Warehouse:
    """A seeded synthetic hall (see the module docstring); aisles run along x."""
    rng = np.random.default_rng(seed)
    boxes: list[tuple[float, float, float, float]] = []
    classes: list[SemanticClass] = []

    def add(box: tuple[float, float, float, float], cls: SemanticClass) -> None:
        boxes.append(box)
        classes.append(cls)

    t = 0.3
    gates = sorted(rng.uniform(10.0, length_m - 10.0, max(1, int(length_m // 30))).tolist())
    edges = [0.0]
    for g in gates:
        if g - 2.0 > edges[-1] + 1.0:
            add((g - 2.0, 0.0, g + 2.0, t + 0.05), _S.GATE)
            edges += [g - 2.0, g + 2.0]
    edges.append(length_m)
    for a, b in zip(edges[::2], edges[1::2], strict=True):
        add((a, 0.0, b, t), _S.WALL)
    add((0.0, width_m - t, length_m, width_m), _S.WALL)
    add((0.0, 0.0, t, width_m), _S.WALL)
    add((length_m - t, 0.0, length_m, width_m), _S.WALL)
    for x in np.arange(12.0, length_m - 12.0, 1.6):
        if rng.random() < 0.5 and all(abs(x - g) > 3.5 for g in gates):
            add((x, 0.8, x + 1.2, 1.6), _S.PALLET)
    rack_x0, rack_x1 = 9.0, length_m - 9.0
    depth = 2.4
    y, row_lines = 7.0, []
    while y + depth + aisle_width_m < width_m - 6.0:
        row_lines.append(y)
        y += depth + aisle_width_m
    n_bays = int((rack_x1 - rack_x0) // bay_m)
    for y0 in row_lines:
        for face_y, inward in ((y0, 1.0), (y0 + depth, -1.0)):
            for k in range(n_bays + 1):
                x = rack_x0 + k * bay_m
                add((x, min(face_y, face_y + 0.1 * inward), x + 0.1, max(face_y, face_y + 0.1 * inward)), _S.RACK)
            for k in range(n_bays):
                for half in (0, 1):
                    if rng.random() < 0.75:
                        x = rack_x0 + k * bay_m + 0.15 + half * 1.25
                        ya, yb = face_y + 0.05 * inward, face_y + 1.05 * inward
                        add((x, min(ya, yb), x + 1.15, max(ya, yb)), _S.PALLET)
    aisle_ys = [4.0] + [y0 + depth + aisle_width_m / 2 for y0 in row_lines[:-1]] + [
        row_lines[-1] + depth + 3.0 if row_lines else width_m - 4.0]
    route = [(4.5, 4.0)]
    for ya in aisle_ys[1:]:
        route += [(4.5, ya), (length_m - 4.5, ya), (length_m - 4.5, 4.0), (4.5, 4.0)]
    route += [(4.5, aisle_ys[1]), (length_m / 2, aisle_ys[1])]
    movers, sizes, mover_classes = [], [], []
    for cls, count, size, speed in ((_S.FORKLIFT, n_forklifts, (2.4, 1.2), 1.5), (_S.HUMAN, n_humans, (0.5, 0.5), 0.8)):
        for _ in range(count):
            ya = aisle_ys[int(rng.integers(1, len(aisle_ys)))] + rng.uniform(-0.6, 0.6)
            xa, xb = sorted(rng.uniform(rack_x0, rack_x1, 2).tolist())
            movers.append((xa, ya, max(xb, xa + 5.0), ya, speed, rng.uniform(0.0, 100.0)))
            sizes.append(size)
            mover_classes.append(cls)
    return Warehouse(length_m, width_m, np.array(boxes), np.array(classes, dtype=np.uint8), np.array(route),
                     np.array(movers).reshape(-1, 6), np.array(sizes).reshape(-1, 2),
                     np.array(mover_classes, dtype=np.uint8))


def truth_labels(warehouse: Warehouse, *, resolution_m: float, tolerance_cells: float = 1.0) -> npt.NDArray[np.uint8]:
    """Static ground truth raster, (rows, cols) uint8 codes, origin (0, 0).

    Every cell a box overlaps takes its class; empty cells within ``tolerance_cells`` of a box take the
    nearest box's class, since surface points a range-noise hair outside a box edge are still that box.
    """
    shape = (math.ceil(warehouse.width_m / resolution_m), math.ceil(warehouse.length_m / resolution_m))
    out = np.zeros(shape, dtype=np.uint8)
    cells = np.floor(warehouse.boxes / resolution_m).astype(np.int64)
    for (c0, r0, c1, r1), cls in zip(cells, warehouse.classes, strict=True):
        out[max(r0, 0): min(r1 + 1, shape[0]), max(c0, 0): min(c1 + 1, shape[1])] = cls
    distance, (rows, cols) = distance_transform_edt(out == 0, return_indices=True)
    return np.where(distance <= tolerance_cells, out[rows, cols], out).astype(np.uint8)


def mover_boxes(warehouse: Warehouse, time_s: float) -> npt.NDArray[np.float64]:
    """Boxes (j, 4) of the movers at ``time_s``."""
    m = warehouse.movers
    if not m.size:
        return np.zeros((0, 4))
    length = np.hypot(m[:, 2] - m[:, 0], m[:, 3] - m[:, 1])
    s = (m[:, 4] * time_s + m[:, 5]) % (2 * length)
    f = np.where(s < length, s, 2 * length - s) / length
    cx, cy = m[:, 0] + f * (m[:, 2] - m[:, 0]), m[:, 1] + f * (m[:, 3] - m[:, 1])
    half = warehouse.mover_sizes / 2
    return np.stack([cx - half[:, 0], cy - half[:, 1], cx + half[:, 0], cy + half[:, 1]], axis=1)


def _cast(origin: npt.NDArray[np.float64], bearings: npt.NDArray[np.float64], boxes: npt.NDArray[np.float64],
          max_range_m: float) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.int64]]:
    """Range to and index of the first box each ray hits (inf, -1 for none), slab method."""
    d = np.stack([np.cos(bearings), np.sin(bearings)], axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / d
        t1 = (boxes[None, :, :2] - origin) * inv[:, None, :]
        t2 = (boxes[None, :, 2:] - origin) * inv[:, None, :]
    t_near = np.nanmax(np.minimum(t1, t2), axis=2)
    t_far = np.nanmin(np.maximum(t1, t2), axis=2)
    hit = (t_near <= t_far) & (t_near > 0.0) & (t_near < max_range_m)
    t = np.where(hit, t_near, np.inf)
    first = np.argmin(t, axis=1) if boxes.shape[0] else np.zeros(bearings.size, dtype=np.int64)
    rng = t[np.arange(bearings.size), first] if boxes.shape[0] else np.full(bearings.size, np.inf)
    return rng, np.where(np.isfinite(rng), first, -1)


class SimulatedRun(NamedTuple):
    """Scans and the truth behind them: ``true_poses`` / ``odometry_poses`` (n, 3) camera poses per scan;
    ``range_scans`` from the lidar (empty without one)."""

    scans: list[ScanObservation]
    true_poses: npt.NDArray[np.float64]
    odometry_poses: npt.NDArray[np.float64]
    range_scans: list[RangeScan]


def _route_poses(route: npt.NDArray[np.float64], step_m: float) -> npt.NDArray[np.float64]:
    out = []
    for a, b in itertools.pairwise(route):
        n = max(1, int(np.hypot(*(b - a)) / step_m))
        f = np.arange(n)[:, None] / n
        xy = a + f * (b - a)
        out.append(np.column_stack([xy, np.full(n, math.atan2(b[1] - a[1], b[0] - a[0]))]))
    poses = np.vstack(out)
    return poses


def simulate_run(
    warehouse: Warehouse,
    *,
    seed: int = 0,
    speed_mps: float = 1.2,
    rate_hz: float = 10.0,
    n_cones: int = 120,
    hfov_rad: float = 1.2,
    camera_yaw_rad: float = 0.5,
    max_range_m: float = 6.0,
    range_sigma_m: float = 0.01,
    label_noise: float = 1.0,
    phantom_rate: float = 0.2,
    odometry_sigma_per_m: float = 0.01,
    odometry_yaw_sigma_per_m: float = 0.001,
    odometry_yaw_bias_per_m: float = 0.0005,
    lidar_beams: int = 0,
    lidar_fov_rad: float = 1.5 * math.pi,
    lidar_range_m: float = 20.0,
    lidar_every: int = 2,
    max_scans: int | None = None,
) -> SimulatedRun:
    """Drive the warehouse route and label what the camera sees (see the module docstring).

    ``label_noise`` scales the per-class error rates (0 labels perfectly); ``phantom_rate`` is the
    chance per frame of a phantom detection; odometry noise is per metre driven, with a yaw bias.
    With ``lidar_beams`` > 0 a forward-facing lidar on the robot's centre line (0.3 m ahead of the
    base, ``lidar_fov_rad`` wide, ``range_sigma_m`` noise) scans every ``lidar_every``-th frame,
    its pose from the same drifting odometry.
    """
    rng = np.random.default_rng(seed)
    step = speed_mps / rate_hz
    base = _route_poses(warehouse.route, step)
    # smooth the corners: heading follows a short moving average so the robot turns over ~1 s
    kernel = max(1, int(rate_hz))
    yaw = np.unwrap(base[:, 2])
    padded = np.pad(yaw, (kernel // 2, kernel - 1 - kernel // 2), mode="edge")
    yaw = np.convolve(padded, np.ones(kernel) / kernel, "valid")
    truth_robot = np.column_stack([base[:, :2], se2.wrap_angle(yaw)])
    if max_scans is not None:
        truth_robot = truth_robot[:max_scans]
    increments = se2.between(truth_robot[:-1], truth_robot[1:])
    dist = np.hypot(increments[:, 0], increments[:, 1])
    noisy = increments.copy()
    noisy[:, :2] += rng.normal(0.0, 1.0, (dist.size, 2)) * (odometry_sigma_per_m * dist)[:, None]
    noisy[:, 2] += rng.normal(0.0, 1.0, dist.size) * odometry_yaw_sigma_per_m * dist + odometry_yaw_bias_per_m * dist
    odom = [truth_robot[0]]
    for inc in noisy:
        odom.append(se2.compose(odom[-1], inc))
    odom_robot = np.array(odom)
    mount = np.array([0.3, 0.0, camera_yaw_rad])
    true_cam, odom_cam = se2.compose(truth_robot, mount), se2.compose(odom_robot, mount)
    static = warehouse.boxes
    small = (static[:, 2] - static[:, 0] < 5.0) & (static[:, 3] - static[:, 1] < 5.0)
    large_ids = np.flatnonzero(~small)
    small_ids = np.flatnonzero(small)
    tree = cKDTree((static[small_ids, :2] + static[small_ids, 2:]) / 2)
    rel_bearings = np.linspace(-hfov_rad / 2, hfov_rad / 2, n_cones)
    lidar_mount = np.array([0.3, 0.0, 0.0])
    true_lidar, odom_lidar = se2.compose(truth_robot, lidar_mount), se2.compose(odom_robot, lidar_mount)
    lidar_bearings = np.linspace(-lidar_fov_rad / 2, lidar_fov_rad / 2, max(lidar_beams, 1))
    range_scans = []
    lidar_rng = np.random.default_rng([seed, 1])  # its own stream: the labels do not change with the lidar
    names = list(CLASS_NAMES)
    classes_all = np.concatenate([warehouse.classes, warehouse.mover_classes])
    scans = []
    t0_ns = 1_700_000_000 * 10**9
    for i, cam in enumerate(true_cam):
        time_s = i / rate_hz
        near = small_ids[tree.query_ball_point(cam[:2], max_range_m + 3.0)]
        ids = np.concatenate([large_ids, near, static.shape[0] + np.arange(warehouse.movers.shape[0])])
        boxes = np.vstack([static, mover_boxes(warehouse, time_s)])[ids]
        ranges, hit = _cast(cam[:2], cam[2] + rel_bearings, boxes, max_range_m)
        seen = hit >= 0
        obj = np.where(seen, ids[np.maximum(hit, 0)], -1)
        truth_cls = classes_all[np.maximum(obj, 0)]
        labels = truth_cls.astype(np.int64) - 1
        conf = rng.beta(8.0, 2.0, n_cones)
        for o in np.unique(obj[seen]):
            cls = SemanticClass(int(classes_all[o]))
            if rng.random() < _ERROR_RATE[cls] * label_noise:
                wrong = list(_CONFUSION[cls])
                pick = wrong[int(rng.choice(len(wrong), p=list(_CONFUSION[cls].values())))]
                members = obj == o
                labels[members] = int(pick) - 1
                conf[members] = rng.beta(4.0, 3.0)
        heights = np.array([_HEIGHT_M[SemanticClass(int(c))] if c else 0.0 for c in truth_cls])
        heights = np.minimum(heights, 3.0) + rng.normal(0.0, 0.05, n_cones)
        ranges = ranges + rng.normal(0.0, range_sigma_m, n_cones)
        if rng.random() < phantom_rate:
            a = int(rng.integers(0, n_cones - 6))
            width = int(rng.integers(2, 6))
            sl = slice(a, a + width)
            ranges[sl] = np.minimum(ranges[sl], rng.uniform(0.8, max_range_m - 0.5))
            seen[sl] = True
            labels[sl] = int(rng.integers(0, len(names)))
            conf[sl] = rng.beta(4.0, 3.0)
            heights[sl] = rng.uniform(0.2, 2.5)
        keep = seen & np.isfinite(ranges) & (ranges > 0.05)
        if lidar_beams and i % lidar_every == 0:
            lidar_near = small_ids[tree.query_ball_point(true_lidar[i, :2], lidar_range_m + 3.0)]
            lidar_ids = np.concatenate([large_ids, lidar_near, static.shape[0] + np.arange(warehouse.movers.shape[0])])
            lidar_boxes = np.vstack([static, mover_boxes(warehouse, time_s)])[lidar_ids]
            lidar_ranges, _ = _cast(true_lidar[i, :2], true_lidar[i, 2] + lidar_bearings, lidar_boxes, lidar_range_m)
            lidar_ranges = lidar_ranges + lidar_rng.normal(0.0, range_sigma_m, lidar_ranges.size)
            range_scans.append(range_scan_from_arrays(
                t0_ns + round(time_s * 1e9), odom_lidar[i], float(lidar_bearings[0]),
                float(lidar_bearings[1] - lidar_bearings[0]) if lidar_beams > 1 else 1.0, lidar_ranges,
                range_max_m=lidar_range_m))
        scans.append(observation_from_arrays(
            t0_ns + round(time_s * 1e9), odom_cam[i], rel_bearings[keep], ranges[keep],
            np.maximum(heights[keep], 0.0), labels[keep], conf[keep], names))
    return SimulatedRun(scans, true_cam, odom_cam, range_scans)
