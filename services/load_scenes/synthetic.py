"""Seeded synthetic rack bays with exact ground truth, noisy box estimates and depth views (tests and bench).

A bay is single or double deep with 2-5 levels and three pallet slots per level. Levels are empty or hold
pallets with a load: one block of goods or a stack of 2-3 cartons; a few front stacks have their top carton
overhanging towards the aisle with its centre of mass beyond the carton below (unstable). In double-deep
bays the second-deep pallets stand behind the front ones; a pallet the camera cannot see is not detected.

The estimates are the truth with Gaussian pose noise of the given sigma, size noise, random misses of
visible objects, the misses of objects the camera hardly sees (hidden objects) and a few false estimates
(ghosts): boxes floating in a level, boxes standing on a beam pair where nothing is, and shifted duplicates of
real objects. Depth points come from casting a pixel grid from an aisle camera at the bay's front against the
true boxes, the beams, the floor and a wall behind the rack, with range noise.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from services.load_scenes.boxes import (
    LOAD,
    PALLET,
    SUPPORT,
    Boxes,
    beam_boxes,
    concat,
    hull_half,
    level_tops,
    supports,
    to_map_frame,
    yaw_to_map,
)
from services.load_scenes.likelihood import Rays, entry_distances
from services.load_scenes.model import Bay, BoxEstimate, DepthEvidence, ObjectKind
from services.load_scenes.predicates import Mask, evidence_predicates, support_relations

PALLET_SIZE = (0.8, 1.2, 0.144)
SLOTS_U = (-0.9, 0.0, 0.9)
WIDTH_M = 2.7
SLOT_DEPTH_M = 1.2
WALL_BEHIND_M = 0.3
MIN_VISIBLE_PIXELS = 12
MIN_GHOST_PIXELS = 30


@dataclass(frozen=True)
class NoiseModel:
    """How the synthetic detector errs."""

    sigma_m: tuple[float, float, float] = (0.02, 0.02, 0.015)
    """Pose noise along the bay's u, v and z, metres (reported as the estimates' sigma)."""
    size_sigma_m: float = 0.01
    yaw_sigma_rad: float = 0.01
    miss_rate: float = 0.03
    """Visible objects the detector misses."""
    ghosts_per_bay: float = 0.3
    range_sigma_m: float = 0.01
    limited_view_rate: float = 0.2
    """Bays whose camera sees only the lower levels."""


@dataclass(frozen=True)
class SyntheticBay:
    """One bay with its truth, its estimates and a depth view."""

    bay: Bay
    truth: Boxes
    """Supports then objects, bay frame."""
    truth_ids: list[str]
    estimates: list[BoxEstimate]
    estimate_truth: dict[str, str | None]
    """Estimate id -> the true object's id, None for a ghost."""
    hidden: set[str]
    """True objects not detected but under a detected object (what the inference should add)."""
    missed: set[str]
    """All true objects not detected."""
    overhanging: set[str]
    evidence: list[DepthEvidence]

    @property
    def ghosts(self) -> set[str]:
        return {e for e, t in self.estimate_truth.items() if t is None}

    def truth_relations(self) -> tuple[Mask, Mask]:
        """``supports[j, i]`` and symmetric ``unstable`` of the true boxes (exact geometry, 5 mm tolerance)."""
        ev = evidence_predicates(self.truth, k_sigma=3.0, min_tolerance_m=0.005)
        return support_relations(ev.contact, ev.rests_on, ev.stable)

    def occupied(self) -> npt.NDArray[np.bool_]:
        """(L,) whether each level holds an object."""
        obj = self.truth.kind != SUPPORT
        return np.isin(np.arange(len(self.bay.levels_z_m)), self.truth.level[obj])


def _box(centre: tuple[float, float, float], size: tuple[float, float, float], kind: int, level: int) -> Boxes:
    s = np.array([size], float)
    return Boxes(centre=np.array([centre], float), half=hull_half(s, np.zeros(1)), size=s, yaw=np.zeros(1),
                 sigma=np.zeros((1, 3)), kind=np.array([kind], np.int64), level=np.array([level], np.int64),
                 score=np.ones(1))


def _loads(rng: np.random.Generator, pallet: Boxes, clear_m: float, level: int, front: bool,
           overhang_rate: float) -> tuple[list[Boxes], bool]:
    """Goods on one pallet: a block or a stack of cartons (the top one maybe overhanging towards the aisle)."""
    pu, pv, _ = pallet.centre[0]
    z = float(pallet.top[0])
    room = clear_m - PALLET_SIZE[2] - 0.05
    if rng.random() < 0.55 or room < 0.6:
        w, d = PALLET_SIZE[0] - rng.uniform(0.0, 0.1), PALLET_SIZE[1] - rng.uniform(0.0, 0.15)
        h = rng.uniform(0.25, max(room, 0.3))
        return [_box((pu + rng.uniform(-0.02, 0.02), pv + rng.uniform(-0.02, 0.02), z + h / 2), (w, d, h),
                     LOAD, level)], False
    n = int(rng.integers(2, 4))
    h = min(rng.uniform(0.25, 0.45), room / n)
    out: list[Boxes] = []
    cu, cv = pu, pv
    w, d = rng.uniform(0.5, 0.78), rng.uniform(0.6, 1.15)
    overhang = front and rng.random() < overhang_rate
    for k in range(n):
        if k == n - 1 and overhang:
            below_front = cv - d / 2
            w2, d2 = rng.uniform(0.4, w), rng.uniform(0.4, 0.7)
            cv = below_front - rng.uniform(0.08, 0.2)  # centre of mass beyond the front face below
            w, d = w2, d2
        else:
            cu, cv = cu + rng.uniform(-0.02, 0.02), cv + rng.uniform(-0.02, 0.02)
        out.append(_box((cu, cv, z + h / 2), (w, d, h), LOAD, level))
        z += h
    return out, overhang


def _bay(rng: np.random.Generator, index: int) -> Bay:
    deep = 2 if rng.random() < 0.4 else 1
    n_levels = int(rng.integers(2, 6))
    pitch = rng.uniform(1.5, 1.9)
    yaw = float(rng.uniform(-math.pi, math.pi))
    levels = tuple(round(i * pitch, 3) for i in range(n_levels))
    key = f"R{index // 20:02d}/{index % 20:03d}"
    return Bay(key=key, row=f"R{index // 20:02d}", aisle=index // 40, bay=index % 20,
               origin=(float(rng.uniform(-50, 50)), float(rng.uniform(-50, 50))), yaw_rad=yaw, width_m=WIDTH_M,
               depth_m=SLOT_DEPTH_M if deep == 1 else 2 * SLOT_DEPTH_M + 0.1, levels_z_m=levels,
               bin_ids=tuple(f"{key}-{lv:02d}" for lv in range(n_levels)), deep=deep)


def _truth(rng: np.random.Generator, bay: Bay, overhang_rate: float) -> tuple[Boxes, set[int]]:
    parts: list[Boxes] = [supports(bay)]
    overhanging: set[int] = set()
    tops = level_tops(bay)
    count = len(bay.levels_z_m)
    for level, z in enumerate(bay.levels_z_m):
        if rng.random() < 0.25:
            continue
        clear = float(tops[level] - z)
        for u in SLOTS_U:
            for pos in range(bay.deep):
                if rng.random() > (0.65 if pos == 0 else 0.8):
                    continue
                v = 0.5 * SLOT_DEPTH_M + pos * (SLOT_DEPTH_M + 0.1)
                pallet = _box((u + rng.uniform(-0.02, 0.02), v + rng.uniform(-0.02, 0.02), z + PALLET_SIZE[2] / 2),
                              PALLET_SIZE, PALLET, level)
                loads, over = _loads(rng, pallet, clear, level, pos == 0, overhang_rate)
                parts.append(pallet)
                count += 1
                parts.extend(loads)
                count += len(loads)
                if over:
                    overhanging.add(count - 1)
    return concat(*parts), overhanging


def _camera(rng: np.random.Generator, bay: Bay, limited: bool) -> tuple[npt.NDArray[np.float64], Rays]:
    """Aisle camera in the bay frame and its pixel rays (a grid of azimuths and elevations)."""
    o = np.array([rng.uniform(-0.3, 0.3), -rng.uniform(1.4, 2.0), rng.uniform(0.8, 1.5)])
    top = float(level_tops(bay)[-1] if not limited else bay.levels_z_m[1] + 0.3)
    az_half = math.atan2(0.5 * WIDTH_M + 0.3, -o[1])
    el_lo = math.atan2(-o[2], -o[1] + 0.2)
    el_hi = math.atan2(top - o[2], -o[1])
    az, el = np.meshgrid(np.linspace(-az_half, az_half, 64), np.linspace(el_lo, el_hi, 96))
    d = np.stack([np.sin(az) * np.cos(el), np.cos(az) * np.cos(el), np.sin(el)], axis=-1).reshape(-1, 3)
    n = d.shape[0]
    origin = np.broadcast_to(o, (n, 3)).copy()
    return o, Rays(origin=origin, direction=d, range_m=np.zeros(n), point=np.zeros((n, 3)),
                   background=np.zeros(n, bool))


def _first_hits(bay: Bay, rays: Rays, boxes: Boxes) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.int64]]:
    """Range of each ray to the first surface and which object it is (-1 beam/floor/wall/nothing)."""
    obj = np.flatnonzero(boxes.kind != SUPPORT)
    t_obj = entry_distances(rays, boxes.centre[obj], boxes.size[obj], boxes.yaw[obj]) if obj.size else (
        np.full((len(rays.origin), 0), np.inf))
    bc, bh = beam_boxes(bay)
    t_beam = entry_distances(rays, bc, 2.0 * bh, np.zeros(len(bc))).min(axis=1, initial=np.inf)
    o, d = rays.origin, rays.direction
    with np.errstate(divide="ignore", invalid="ignore"):
        t_floor = np.where(d[:, 2] < 0, -o[:, 2] / d[:, 2], np.inf)
        t_wall = np.where(d[:, 1] > 0, (bay.depth_m + WALL_BEHIND_M - o[:, 1]) / d[:, 1], np.inf)
    t_env = np.minimum(np.minimum(t_beam, t_floor), t_wall)
    if obj.size:
        k = t_obj.argmin(axis=1)
        t_k = t_obj[np.arange(len(k)), k]
        which = np.where(t_k < t_env, obj[k], -1)
        return np.minimum(t_k, t_env), which
    return t_env, np.full(len(t_env), -1)


def synthetic_bay(seed: int, index: int, noise: NoiseModel | None = None, *, overhang_rate: float = 0.08,
                  stamp_ns: int = 1_700_000_000_000_000_000) -> SyntheticBay:
    """One seeded bay: truth, estimates and a depth view. ``index`` varies the bay within a seed."""
    nm = noise or NoiseModel()
    rng = np.random.default_rng([seed, index])
    bay = _bay(rng, index)
    truth, overhanging = _truth(rng, bay, overhang_rate)
    n_sup = len(bay.levels_z_m)
    ids = [f"{bay.key}/L{i}" for i in range(n_sup)] + [f"{bay.key}/t{i}" for i in range(n_sup, len(truth))]
    cam, pixels = _camera(rng, bay, rng.random() < nm.limited_view_rate)
    ranges, which = _first_hits(bay, pixels, truth)
    pixel_counts = np.bincount(which[which >= 0], minlength=len(truth))
    finite = np.isfinite(ranges)
    noisy = ranges[finite] + rng.normal(0.0, nm.range_sigma_m, int(finite.sum()))
    points = pixels.origin[finite] + pixels.direction[finite] * noisy[:, None]
    cam_map = to_map_frame(bay, cam[None])[0]
    evidence = [DepthEvidence(origin=(float(cam_map[0]), float(cam_map[1]), float(cam_map[2])),
                              points=to_map_frame(bay, points), stamp_ns=stamp_ns)]

    ev = evidence_predicates(truth, k_sigma=3.0, min_tolerance_m=0.005)
    estimates: list[BoxEstimate] = []
    est_truth: dict[str, str | None] = {}
    detected = np.zeros(len(truth), bool)
    for i in range(n_sup, len(truth)):
        detected[i] = pixel_counts[i] >= MIN_VISIBLE_PIXELS and rng.random() >= nm.miss_rate
    sigma = np.array(nm.sigma_m)
    for i in np.flatnonzero(detected).tolist():
        e = _estimate(bay, rng, nm, truth, i, f"{bay.key}/e{len(estimates)}", stamp_ns,
                      rng.uniform(0.6, 1.0), sigma)
        estimates.append(e)
        est_truth[e.id] = ids[i]
    for _ in range(int(rng.poisson(nm.ghosts_per_bay))):
        ghost = _ghost(rng, bay, truth, pixels, ranges)
        if ghost is not None:
            e = _estimate(bay, rng, nm, ghost, 0, f"{bay.key}/e{len(estimates)}", stamp_ns,
                          rng.uniform(0.3, 0.8), sigma)
            estimates.append(e)
            est_truth[e.id] = None
    order = rng.permutation(len(estimates))
    estimates = [estimates[k] for k in order]
    missed = {ids[i] for i in range(n_sup, len(truth)) if not detected[i]}
    carried = ev.rests_on & detected[:, None]
    hidden = {ids[j] for j in range(n_sup, len(truth)) if not detected[j] and carried[:, j].any()}
    return SyntheticBay(bay=bay, truth=truth, truth_ids=ids, estimates=estimates, estimate_truth=est_truth,
                        hidden=hidden, missed=missed, overhanging={ids[i] for i in overhanging}, evidence=evidence)


def _estimate(bay: Bay, rng: np.random.Generator, nm: NoiseModel, boxes: Boxes, i: int, est_id: str,
              stamp_ns: int, score: float, sigma: npt.NDArray[np.float64]) -> BoxEstimate:
    """A noisy map-frame estimate of box i (sigma along the bay's axes, reported per map axis)."""
    c = boxes.centre[i] + rng.normal(0.0, 1.0, 3) * sigma
    size = np.maximum(boxes.size[i] + rng.normal(0.0, nm.size_sigma_m, 3), 0.05)
    yaw = yaw_to_map(bay, np.array([boxes.yaw[i] + rng.normal(0.0, nm.yaw_sigma_rad)]))[0]
    cm = to_map_frame(bay, c[None])[0]
    s_uv = math.hypot(sigma[0], sigma[1]) / math.sqrt(2.0)
    kind = ObjectKind.PALLET if boxes.kind[i] == PALLET else ObjectKind.LOAD
    return BoxEstimate(id=est_id, kind=kind, centre=(float(cm[0]), float(cm[1]), float(cm[2])),
                       size=(float(size[0]), float(size[1]), float(size[2])), yaw_rad=float(yaw),
                       sigma=(s_uv, s_uv, float(sigma[2])), sigma_yaw_rad=nm.yaw_sigma_rad, score=float(score),
                       stamp_ns=stamp_ns, bay=bay.key)


def _ghost(rng: np.random.Generator, bay: Bay, truth: Boxes, pixels: Rays,
           ranges: npt.NDArray[np.float64]) -> Boxes | None:
    """A false box the camera would see through: floating, standing on a beam pair, or a shifted duplicate."""
    n_sup = len(bay.levels_z_m)
    for _ in range(10):
        kind = rng.integers(0, 3)
        level = int(rng.integers(0, n_sup))
        z0 = bay.levels_z_m[level]
        if kind == 2 and len(truth) > n_sup:
            j = int(rng.integers(n_sup, len(truth)))
            c = truth.centre[j] + np.array([rng.choice([-1, 1]) * rng.uniform(0.15, 0.3), 0.0, 0.0])
            sz = truth.size[j]
            box = _box((float(c[0]), float(c[1]), float(c[2])), (float(sz[0]), float(sz[1]), float(sz[2])),
                       int(truth.kind[j]), int(truth.level[j]))
        elif kind == 1:
            slot = float(rng.choice(SLOTS_U))
            box = _box((slot, 0.5 * SLOT_DEPTH_M, z0 + PALLET_SIZE[2] / 2), PALLET_SIZE, PALLET, level)
        else:
            size = (rng.uniform(0.3, 0.7), rng.uniform(0.3, 0.8), rng.uniform(0.2, 0.5))
            c = (rng.uniform(-1.0, 1.0), rng.uniform(0.2, 0.6), z0 + rng.uniform(0.3, 0.8) + size[2] / 2)
            box = _box(c, size, LOAD, level)
        t = entry_distances(pixels, box.centre, box.size, box.yaw)[:, 0]
        seen_through = np.isfinite(t) & (ranges > t + 0.1)
        if seen_through.sum() >= MIN_GHOST_PIXELS:
            return box
    return None
