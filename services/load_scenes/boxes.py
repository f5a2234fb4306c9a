"""A bay's boxes as arrays in the bay frame, the rack model's supports, and the checks of estimates at the edge.

Bay frame: ``u`` along the front opening (the bay's width, 0 in the middle), ``v`` into the rack from the
front edge (0 at the front, ``depth_m`` at the back), ``z`` up from the floor. With the bay's ``yaw_rad`` the
direction of ``v`` in the map, ``u`` is ``(sin yaw, -cos yaw)`` so that (u, v, z) is right-handed.
Every box here stands upright (only a yaw), so its extent along u and v is the axis-aligned hull of its
footprint turned by its yaw relative to the bay (``half``); ray casting uses the true turned box.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
import numpy.typing as npt

from services.load_scenes.errors import SceneError
from services.load_scenes.model import Bay, BoxEstimate, ObjectKind, SceneNode

SUPPORT, PALLET, LOAD = 0, 1, 2
"""Kind codes of the arrays: a level's beam pair (or the floor), a pallet, a load."""
KIND_CODE = {ObjectKind.BEAM: SUPPORT, ObjectKind.PALLET: PALLET, ObjectKind.LOAD: LOAD}
CODE_KIND = {code: kind for kind, code in KIND_CODE.items()}

BEAM_DEPTH_M = 0.1
"""Depth of one beam (along v); beams stand at the front and back of each pallet position."""
FLOOR_THICKNESS_M = 0.1


@dataclass(frozen=True, slots=True)
class Boxes:
    """K upright boxes in the bay frame (supports first, then objects).

    Attributes
    ----------
    centre, half : (K, 3) float64
        Centre and half extent (axis-aligned hull in the bay frame) along u, v, z, metres.
    size : (K, 3) float64
        The box's own size (along its turned x, y and z), metres.
    yaw : (K,) float64
        Turn of the box's x axis from the bay's u axis, radians.
    sigma : (K, 3) float64
        One standard deviation of the centre along u, v, z, metres (0 for the rack model's supports).
    kind : (K,) int64
        ``SUPPORT``, ``PALLET`` or ``LOAD``.
    level : (K,) int64
        Level the box stands in (the support it is nearest above), -1 when below the floor.
    score : (K,) float64
        Detection confidence (1 for supports).
    """

    centre: npt.NDArray[np.float64]
    half: npt.NDArray[np.float64]
    size: npt.NDArray[np.float64]
    yaw: npt.NDArray[np.float64]
    sigma: npt.NDArray[np.float64]
    kind: npt.NDArray[np.int64]
    level: npt.NDArray[np.int64]
    score: npt.NDArray[np.float64]

    def __len__(self) -> int:
        return int(self.kind.shape[0])

    @property
    def bottom(self) -> npt.NDArray[np.float64]:
        return self.centre[:, 2] - self.half[:, 2]

    @property
    def top(self) -> npt.NDArray[np.float64]:
        return self.centre[:, 2] + self.half[:, 2]


class Skipped(NamedTuple):
    """An estimate left out of a scene, and why."""

    id: str
    reason: str


def hull_half(size: npt.NDArray[np.float64], yaw: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    """Half extents (K, 3) along u, v, z of upright boxes of ``size`` (K, 3) turned by ``yaw`` (K,) rad."""
    c, s = np.abs(np.cos(yaw)), np.abs(np.sin(yaw))
    return 0.5 * np.stack([c * size[:, 0] + s * size[:, 1], s * size[:, 0] + c * size[:, 1], size[:, 2]], axis=1)


def to_bay_frame(bay: Bay, xyz: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    """Map-frame points (N, 3) to the bay frame (N, 3): u along the front, v into the rack, z up."""
    sy, cy = math.sin(bay.yaw_rad), math.cos(bay.yaw_rad)
    dx, dy = xyz[:, 0] - bay.origin[0], xyz[:, 1] - bay.origin[1]
    return np.stack([dx * sy - dy * cy, dx * cy + dy * sy, xyz[:, 2]], axis=1)


def to_map_frame(bay: Bay, uvz: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    """Bay-frame points (N, 3) back to the map frame (N, 3)."""
    sy, cy = math.sin(bay.yaw_rad), math.cos(bay.yaw_rad)
    u, v = uvz[:, 0], uvz[:, 1]
    return np.stack([bay.origin[0] + u * sy + v * cy, bay.origin[1] - u * cy + v * sy, uvz[:, 2]], axis=1)


def yaw_to_bay(bay: Bay, yaw_rad: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    """Map-frame box yaws to turns from the bay's u axis, wrapped to [-pi, pi)."""
    rel = yaw_rad - (bay.yaw_rad - 0.5 * math.pi)
    return (rel + math.pi) % (2.0 * math.pi) - math.pi


def yaw_to_map(bay: Bay, yaw_rel: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    """Turns from the bay's u axis back to map-frame yaws, wrapped to [-pi, pi)."""
    out = yaw_rel + (bay.yaw_rad - 0.5 * math.pi)
    return (out + math.pi) % (2.0 * math.pi) - math.pi


def validate_bay(bay: Bay) -> None:
    """Reject a bay the scene cannot be built in (no levels, levels out of order, bins not one per level).

    Raises
    ------
    SceneError
        With the bay's key and what is wrong.
    """
    z = np.asarray(bay.levels_z_m, float)
    if z.size == 0:
        raise SceneError(f"bay {bay.key!r} has no levels (no rack model)")
    if not np.all(np.isfinite(z)) or np.any(np.diff(z) <= 0.0) or z[0] < 0.0:
        raise SceneError(f"bay {bay.key!r} levels must be finite, >= 0 and rising, got {bay.levels_z_m}")
    if len(bay.bin_ids) != z.size:
        raise SceneError(f"bay {bay.key!r} has {z.size} levels but {len(bay.bin_ids)} bin ids")
    dims = (bay.width_m, bay.depth_m, bay.beam_height_m, bay.yaw_rad, *bay.origin)
    if not all(math.isfinite(d) for d in dims) or min(bay.width_m, bay.depth_m, bay.beam_height_m) <= 0.0:
        raise SceneError(f"bay {bay.key!r} needs a finite pose and positive width, depth and beam height")
    if bay.deep not in (1, 2):
        raise SceneError(f"bay {bay.key!r}: deep must be 1 or 2, got {bay.deep}")


def level_tops(bay: Bay) -> npt.NDArray[np.float64]:
    """Top of each level's clear space (the next beam's underside; the highest level gets 2 m), metres."""
    z = np.asarray(bay.levels_z_m, float)
    return np.append(z[1:] - bay.beam_height_m, z[-1] + 2.0)


def supports(bay: Bay) -> Boxes:
    """One support per level in the bay frame: the floor slab at level 0, the beam pair's span above.

    A level's beam pair acts as the table of seed 003: one slab over the bay's whole width and depth whose
    top is the level's z (what a pallet rests on), ``beam_height_m`` thick. Ray casting uses the real beams
    (:func:`beam_boxes`).
    """
    z = np.asarray(bay.levels_z_m, float)
    n = z.size
    thick = np.where(z <= 0.0, FLOOR_THICKNESS_M, bay.beam_height_m)
    centre = np.stack([np.zeros(n), np.full(n, 0.5 * bay.depth_m), z - 0.5 * thick], axis=1)
    size = np.stack([np.full(n, bay.width_m), np.full(n, bay.depth_m), thick], axis=1)
    return Boxes(centre=centre, half=0.5 * size, size=size, yaw=np.zeros(n), sigma=np.zeros((n, 3)),
                 kind=np.full(n, SUPPORT, np.int64), level=np.arange(n, dtype=np.int64), score=np.ones(n))


def beam_boxes(bay: Bay) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """The beams a camera sees: centre and half extent (B, 3) in the bay frame, front and back of each position.

    A single-deep bay has a front and a back beam per level above the floor; a double-deep one also a
    middle pair where the two pallet positions meet.
    """
    z = np.asarray(bay.levels_z_m, float)
    z = z[z > 0.0]
    edges = [0.0, bay.depth_m] if bay.deep == 1 else [0.0, 0.5 * bay.depth_m - BEAM_DEPTH_M, bay.depth_m]
    vs = np.array([min(max(e, 0.0), bay.depth_m - BEAM_DEPTH_M) + 0.5 * BEAM_DEPTH_M for e in edges])
    vv, zz = np.meshgrid(vs, z, indexing="ij")
    centre = np.stack([np.zeros(vv.size), vv.ravel(), zz.ravel() - 0.5 * bay.beam_height_m], axis=1)
    half = np.tile([0.5 * bay.width_m, 0.5 * BEAM_DEPTH_M, 0.5 * bay.beam_height_m], (vv.size, 1))
    return centre, half


def usable_estimates(
    bay: Bay, estimates: list[BoxEstimate], *, margin_m: float = 0.3,
) -> tuple[Boxes, list[BoxEstimate], list[Skipped]]:
    """The usable estimates of one bay as bay-frame :class:`Boxes`, the estimates kept and those skipped.

    Estimates are skipped (with a reason, never raised) when their numbers are not finite, their size or
    sigma is not positive, their score is outside [0, 1], they are beams (the rack model gives the beams),
    they name another bay, or their centre lies more than ``margin_m`` outside the bay's volume.
    """
    kept: list[BoxEstimate] = []
    skipped: list[Skipped] = []
    top = level_tops(bay)[-1]
    for e in estimates:
        nums = (*e.centre, *e.size, e.yaw_rad, *e.sigma, e.sigma_yaw_rad, e.score)
        if not all(math.isfinite(x) for x in nums):
            skipped.append(Skipped(e.id, "pose, size, sigma or score is not finite"))
        elif min(e.size) <= 0.0:
            skipped.append(Skipped(e.id, f"size {e.size} is not positive"))
        elif min(e.sigma) <= 0.0 or e.sigma_yaw_rad < 0.0:
            skipped.append(Skipped(e.id, f"sigma {e.sigma} is not positive"))
        elif not 0.0 <= e.score <= 1.0:
            skipped.append(Skipped(e.id, f"score {e.score} is outside [0, 1]"))
        elif e.kind == ObjectKind.BEAM:
            skipped.append(Skipped(e.id, "beams come from the rack model"))
        elif e.bay is not None and e.bay != bay.key:
            skipped.append(Skipped(e.id, f"estimate is in bay {e.bay!r}, not {bay.key!r}"))
        else:
            u, v, z = to_bay_frame(bay, np.array([e.centre], float))[0]
            inside = (abs(u) <= 0.5 * bay.width_m + margin_m and -margin_m <= v <= bay.depth_m + margin_m
                      and -margin_m <= z <= top + margin_m)
            if inside:
                kept.append(e)
            else:
                skipped.append(Skipped(e.id, f"centre ({u:.2f}, {v:.2f}, {z:.2f}) m is outside the bay"))
    return boxes_from_estimates(bay, kept), kept, skipped


def boxes_from_estimates(bay: Bay, estimates: list[BoxEstimate]) -> Boxes:
    """Bay-frame boxes of valid estimates (no checks: see :func:`usable_estimates`)."""
    n = len(estimates)
    centre = to_bay_frame(bay, np.array([e.centre for e in estimates], float).reshape(n, 3))
    size = np.array([e.size for e in estimates], float).reshape(n, 3)
    yaw = yaw_to_bay(bay, np.array([e.yaw_rad for e in estimates], float))
    sig = np.array([e.sigma for e in estimates], float).reshape(n, 3)
    sy, cy = math.sin(bay.yaw_rad), math.cos(bay.yaw_rad)
    sigma = np.stack([np.hypot(sig[:, 0] * sy, sig[:, 1] * cy), np.hypot(sig[:, 0] * cy, sig[:, 1] * sy),
                      sig[:, 2]], axis=1)
    half = hull_half(size, yaw)
    kind = np.array([KIND_CODE[e.kind] for e in estimates], np.int64)
    return Boxes(centre=centre, half=half, size=size, yaw=yaw, sigma=sigma, kind=kind,
                 level=levels_of(bay, centre[:, 2] - half[:, 2]),
                 score=np.array([e.score for e in estimates], float))


def boxes_from_nodes(bay: Bay, nodes: list[SceneNode]) -> Boxes:
    """Bay-frame boxes of scene nodes (sigma 0, score 1), e.g. to cast rays against a graph's objects."""
    n = len(nodes)
    centre = to_bay_frame(bay, np.array([nd.centre for nd in nodes], float).reshape(n, 3))
    size = np.array([nd.size for nd in nodes], float).reshape(n, 3)
    yaw = yaw_to_bay(bay, np.array([nd.yaw_rad for nd in nodes], float))
    half = hull_half(size, yaw)
    return Boxes(centre=centre, half=half, size=size, yaw=yaw, sigma=np.zeros((n, 3)),
                 kind=np.array([KIND_CODE[nd.kind] for nd in nodes], np.int64),
                 level=levels_of(bay, centre[:, 2] - half[:, 2]), score=np.ones(n))


def levels_of(bay: Bay, bottom_z: npt.NDArray[np.float64], *, tolerance_m: float = 0.1) -> npt.NDArray[np.int64]:
    """Level each box bottom (metres) stands in: the highest level whose support is at most ``tolerance_m`` above."""
    z = np.asarray(bay.levels_z_m, float)
    return (np.searchsorted(z, bottom_z + tolerance_m, side="right") - 1).astype(np.int64)


def concat(*parts: Boxes) -> Boxes:
    """Boxes of several sets one after the other."""
    return Boxes(*(np.concatenate([getattr(p, f.name) for p in parts]) for f in dataclasses.fields(Boxes)))
