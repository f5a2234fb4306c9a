"""Box estimates at rack faces: pallets, loads and beams from one RGB-D depth image and the rack model.

A rack face seen from the aisle is a set of front faces: beams across the bay, pallets on the beams (or the
floor), cartons on the pallets. Per bay in view the depth points are cropped to the bay's volume and cut into
its levels (between one level's support and the next beam's underside); each level's points are binned into a
front-view grid over (across the bay, height), whose cells keep their mean depth into the rack. Cells where the
depth jumps (the edge of a carton standing further back, the gap between two pallets) are cut, the rest falls
apart into connected components, one object front each. A component resting on the level is a pallet (its
lowest ``pallet_height_m``) with what stands above it as loads; one standing higher is a load. What a front
view cannot see, the depth of a box, comes from the rack model: a pallet is as deep as its position, a load
is taken to be centred on it; the sigmas say so.

Bay frame (as :mod:`services.load_scenes.model` and the inference use it): ``u`` along the front opening,
``(sin yaw, -cos yaw)`` in the map, 0 in the middle; ``v`` into the rack from the front edge; ``z`` up.
"""

from __future__ import annotations

import math
from collections import defaultdict
from collections.abc import Sequence
from typing import Any, NamedTuple

import cv2
import numpy as np
import numpy.typing as npt

from services.load_scenes.errors import LoadScenesError
from services.load_scenes.frames import Intrinsics
from services.load_scenes.model import Bay, BoxEstimate, DepthEvidence, ObjectKind
from shared.bins import Bin
from shared.settings import RackProfileSettings

FloatArray = npt.NDArray[np.float64]

FRONT_REACH_M = 0.6
"""How far in front of a bay's opening (into the aisle) its objects may reach (overhanging loads)."""
TOP_HEIGHT_M = 2.0
BEHIND_M = 0.1
"""Rays through a bay that meet nothing in it are kept as a point this far behind its back (background)."""
"""Height above the top level that still belongs to the bay (its loads)."""
_SEAM_M = 0.015
"""Height above a pallet's top left out of the loads standing on it (points of both meet there)."""
_OCCLUDER_M = 0.3
"""A surface this much nearer beside or below an object hides part of it (an object in a position in front)."""


class RackView(NamedTuple):
    """What one depth image shows of the racks: box estimates and, per bay key, the depth evidence."""

    boxes: tuple[BoxEstimate, ...]
    evidence: dict[str, DepthEvidence]


def bays_from_bins(bins: Sequence[Bin], *, profiles: Sequence[RackProfileSettings] = (), beam_height_m: float = 0.12,
                   double_deep_min_m: float = 1.8) -> list[Bay]:
    """The rack bays the pillar stage's bins make: one per (row, bay), its levels from the bins' levels.

    Bins are the map's ``bin`` records (:class:`shared.bins.Bin`, front edge first in the footprint). A bay's
    bins share a footprint and differ in level; a bin without a level (no rack profile covered it when the
    pillar stage stored it) gets the levels of ``profiles`` at its centre, as the pillar stage would give them.
    Bins without a footprint, aisle or bay, or with no level either way, make no bay (they are left out).

    Parameters
    ----------
    bins : sequence of Bin
        The map's bins.
    profiles : sequence of RackProfileSettings, optional
        The site's rack profiles (``settings.pillars.rack_profiles``): the first whose area holds a bin's centre,
        else the first without an area, as the pillar stage picks them.
    beam_height_m : float
        Vertical size of a beam, metres.
    double_deep_min_m : float
        Bays at least this deep hold two pallets one behind the other, metres.

    Returns
    -------
    list of Bay
        Sorted by key; ``key`` is ``row/BBB`` (the aisle ``AA`` where the bin has no row).

    Raises
    ------
    LoadScenesError
        A bin's footprint is degenerate (fewer than 3 points, or a zero-length front edge).
    """
    groups: dict[tuple[str, int], list[tuple[int, float, str]]] = defaultdict(list)
    shape: dict[tuple[str, int], Bin] = {}
    for record in bins:
        if record.footprint is None or record.aisle is None or record.bay is None:
            continue
        key = (record.row or f"{record.aisle:02d}", record.bay)
        if record.level is not None and record.z_m is not None:
            groups[key].append((record.level, record.z_m, record.id))
        else:
            levels_m = _levels_at(profiles, record.centre)
            if levels_m is None:
                continue
            groups[key].extend((level, z, f"{record.id}-{level + 1:02d}") for level, z in enumerate(levels_m))
        shape.setdefault(key, record)
    bays = []
    for key in sorted(groups):
        levels = sorted(set(groups[key]))
        bays.append(_bay(shape[key], f"{key[0]}/{key[1]:03d}", levels, beam_height_m, double_deep_min_m))
    return bays


def _levels_at(profiles: Sequence[RackProfileSettings], xy: tuple[float, float]) -> list[float] | None:
    """Level heights of the profile for a point: the first whose area holds it, else the first without an area."""
    for profile in profiles:
        if profile.area is not None:
            contour = np.asarray(profile.area, dtype=np.float32).reshape(-1, 1, 2)
            if cv2.pointPolygonTest(contour, (float(xy[0]), float(xy[1])), False) >= 0:
                return profile.levels_m
    return next((p.levels_m for p in profiles if p.area is None), None)


def _bay(record: Bin, key: str, levels: list[tuple[int, float, str]], beam_height_m: float,
         double_deep_min_m: float) -> Bay:
    footprint = np.asarray(record.footprint, dtype=np.float64)
    if len(footprint) < 3 or not np.all(np.isfinite(footprint)):
        raise LoadScenesError(f"bin {record.id}: footprint needs at least 3 finite points, got {record.footprint}")
    left, right = footprint[0], footprint[1]
    width = float(np.hypot(*(right - left)))
    if width <= 1e-6:
        raise LoadScenesError(f"bin {record.id}: the footprint's front edge has no length")
    along = (right - left) / width
    inward = np.array([-along[1], along[0]])
    origin = 0.5 * (left + right)
    if float(np.mean((footprint - origin) @ inward)) < 0:
        inward = -inward
    depth = float(np.max((footprint - origin) @ inward))
    return Bay(key=key, row=record.row or f"{record.aisle:02d}", aisle=int(record.aisle or 0), bay=int(record.bay or 0),
               origin=(float(origin[0]), float(origin[1])), yaw_rad=math.atan2(inward[1], inward[0]), width_m=width,
               depth_m=depth, levels_z_m=tuple(z for _, z, _ in levels), bin_ids=tuple(i for _, _, i in levels),
               beam_height_m=beam_height_m, deep=2 if depth >= double_deep_min_m else 1)


def merge_views(estimates: Sequence[BoxEstimate], *, distance_m: float = 0.25) -> list[BoxEstimate]:
    """One estimate per object of estimates from several views: those of one kind, bay and level whose centres
    lie within ``distance_m`` of each other (map metres) are one object, seen again.

    The merged box averages centre and size weighted by score; its sigmas shrink with the square root of the
    views (independent depth noise), its score is the chance that at least one view was right, its stamp the
    newest, its id the first view's. Estimates without a bay or level are left out.
    """
    groups: list[list[BoxEstimate]] = []
    for est in sorted((e for e in estimates if e.bay is not None and e.level is not None), key=lambda e: -e.score):
        at = np.asarray(est.centre)
        home = next((g for g in groups if g[0].kind is est.kind and g[0].bay == est.bay and g[0].level == est.level
                     and float(np.linalg.norm(np.asarray(g[0].centre) - at)) <= distance_m), None)
        if home is None:
            groups.append([est])
        else:
            home.append(est)
    out = []
    for group in groups:
        if len(group) == 1:
            out.append(group[0])
            continue
        weight = np.array([e.score for e in group])
        weight = weight / weight.sum()
        first = min(group, key=lambda e: e.stamp_ns)
        root = math.sqrt(len(group))
        centre = tuple(float(x) for x in weight @ np.array([e.centre for e in group]))
        size = tuple(float(x) for x in weight @ np.array([e.size for e in group]))
        sigma = tuple(float(x) / root for x in np.min([e.sigma for e in group], axis=0))
        out.append(BoxEstimate(id=first.id, kind=first.kind, centre=(centre[0], centre[1], centre[2]),
                               size=(size[0], size[1], size[2]), yaw_rad=first.yaw_rad,
                               sigma=(sigma[0], sigma[1], sigma[2]),
                               sigma_yaw_rad=min(e.sigma_yaw_rad for e in group) / root,
                               score=1.0 - math.prod(1.0 - e.score for e in group),
                               stamp_ns=max(e.stamp_ns for e in group), bay=first.bay, level=first.level))
    return out


def _check(depth: npt.NDArray[Any], intrinsics: Intrinsics, world_from_optical: npt.NDArray[Any],
           bays: Sequence[Bay], stride: int) -> tuple[npt.NDArray[np.float32], FloatArray]:
    """The depth image in metres (0 where none) and the pose, or a :class:`LoadScenesError` saying what is wrong."""
    if not bays:
        raise LoadScenesError("no bays: the rack model is empty (no bins with levels in the map?)")
    if stride < 1:
        raise LoadScenesError(f"stride must be >= 1, got {stride}")
    image = np.asarray(depth)
    if image.ndim != 2 or image.shape != (intrinsics.height, intrinsics.width):
        raise LoadScenesError(f"depth image of shape {image.shape} does not match the {intrinsics.width}x"
                              f"{intrinsics.height} camera model")
    if image.dtype == np.uint16:
        metres = image.astype(np.float32) * np.float32(1e-3)
    elif np.issubdtype(image.dtype, np.floating):
        if np.isnan(image).any():
            raise LoadScenesError(f"depth image holds {int(np.isnan(image).sum())} NaN pixels (use 0 for no depth)")
        metres = np.where(np.isfinite(image), image, 0.0).astype(np.float32)
        if (metres < 0).any():
            raise LoadScenesError("depth image holds negative depths")
    else:
        raise LoadScenesError(f"depth image must be uint16 millimetres or float metres, got {image.dtype}")
    if not metres.any():
        raise LoadScenesError("depth image holds no depth (all pixels are 0)")
    pose = np.asarray(world_from_optical, dtype=np.float64)
    if pose.shape != (4, 4) or not np.all(np.isfinite(pose)):
        raise LoadScenesError(f"camera pose must be a finite 4x4 matrix, got shape {pose.shape}")
    if not np.allclose(pose[:3, :3] @ pose[:3, :3].T, np.eye(3), atol=1e-4):
        raise LoadScenesError("camera pose's rotation is not orthonormal")
    return metres, pose


def estimate_boxes(depth: npt.NDArray[Any], intrinsics: Intrinsics, world_from_optical: npt.NDArray[Any],
                   bays: Sequence[Bay], *, stamp_ns: int, stride: int = 2, max_range_m: float = 5.0,
                   cell_m: float = 0.04, edge_m: float = 0.04, pallet_height_m: float = 0.15,
                   pallet_width_m: float = 1.2, pallet_depth_m: float | None = None,
                   min_area_m2: float = 0.02, min_width_m: float = 0.15,
                   depth_sigma_m: tuple[float, float] = (0.0012, 0.0019), max_evidence_points: int = 4000,
                   upright_margin_m: float = 0.15) -> RackView:
    """Pallets, loads and beams in the bays a depth image sees, in the map frame, and each bay's depth evidence.

    Parameters
    ----------
    depth : (height, width) uint16 millimetres or float metres
        The registered depth image; 0 (or inf) where there is no measurement, NaN is refused.
    intrinsics : Intrinsics
        The depth camera's model (:func:`services.load_scenes.frames.intrinsics_from_camera_info`; any pinhole
        model with ``fx, fy, cx, cy, width, height`` does).
    world_from_optical : (4, 4) float
        Pose of the optical frame (x right, y down, z forward) in the map, metres.
    bays : sequence of Bay
        The rack model (:func:`bays_from_bins`); bays out of range are skipped.
    stamp_ns : int
        The image's stamp, copied into every estimate.
    stride : int
        Every ``stride``-th row and column is used.
    max_range_m : float
        Depths beyond this are ignored, metres.
    cell_m : float
        Side of the front-view grid's cells, metres.
    edge_m : float
        A jump in mean depth between neighbouring cells larger than this separates two objects, metres.
    pallet_height_m : float
        Height of a pallet (the bottom band of an object resting on a level), metres.
    pallet_width_m : float
        Width of a pallet across the bay, metres: a pallet partly hidden (by an upright, or seen beside an object
        in front of it) is kept only when it shows at least 85 % of it; a partly hidden load is left out.
    pallet_depth_m : float, optional
        Depth of a pallet into the rack (a front view does not see it), metres; default a pallet position's
        depth (the bay's over ``deep``) less 0.15 m.
    min_area_m2 : float
        Front faces smaller than this are left out (noise), square metres.
    min_width_m : float
        Front faces narrower than this are left out (uprights, side faces seen edge-on), metres.
    depth_sigma_m : (float, float)
        Axial depth noise ``a + b * (z - 0.4 m)^2`` (a in metres, b per metre), for the sigmas.
    max_evidence_points : int
        Each bay's evidence keeps at most this many points (evenly thinned).
    upright_margin_m : float
        The evidence leaves out this much of each side of a bay (its uprights, which the scene does not model),
        metres.

    Returns
    -------
    RackView
        Estimates tied to bay and level (objects cut by the image border are left out: another view sees them
        whole), and a :class:`DepthEvidence` per bay with points in its volume (uprights left out).

    Raises
    ------
    LoadScenesError
        No bays, a depth image not matching the camera model, NaN or negative depths, an empty image, a camera
        pose that is not a rigid transform.
    """
    metres, pose = _check(depth, intrinsics, world_from_optical, bays, stride)
    sub = metres[::stride, ::stride]
    rows, cols = np.nonzero((sub > 0) & (sub <= max_range_m))
    z_opt = sub[rows, cols].astype(np.float64)
    u_px, v_px = cols * stride, rows * stride
    x = (u_px - intrinsics.cx) * z_opt / intrinsics.fx
    y = (v_px - intrinsics.cy) * z_opt / intrinsics.fy
    points = np.column_stack((x, y, z_opt)) @ pose[:3, :3].T + pose[:3, 3]
    border = ((u_px < 2 * stride) | (u_px >= intrinsics.width - 2 * stride)
              | (v_px < 2 * stride) | (v_px >= intrinsics.height - 2 * stride))
    noise = depth_sigma_m[0] + depth_sigma_m[1] * (z_opt - 0.4) ** 2
    hidden = _occluded(sub)[rows, cols]
    centre = pose[:3, 3]
    sparse = points[::16]
    # Rays of every other used pixel with their range (inf: no return or too far): a ray that passes through
    # an empty bin and meets nothing in the bay still says the bin is seen and empty (a top bin against open space).
    ray_sub = metres[::2 * stride, ::2 * stride]
    ray_rows, ray_cols = np.indices(ray_sub.shape).reshape(2, -1) * 2 * stride
    ray_range = ray_sub.ravel().astype(np.float64)
    ray_range = np.where((ray_range > 0) & (ray_range <= max_range_m), ray_range, np.inf)
    ray_dir = np.column_stack(((ray_cols - intrinsics.cx) / intrinsics.fx, (ray_rows - intrinsics.cy) / intrinsics.fy,
                               np.ones(ray_cols.size))) @ pose[:3, :3].T  # optical z = 1: range is along z

    boxes: list[BoxEstimate] = []
    evidence: dict[str, DepthEvidence] = {}
    settings = _Grid(cell_m, edge_m, pallet_height_m, max(2, round(min_area_m2 / cell_m**2)), min_width_m,
                     pallet_width_m, pallet_depth_m)
    for bay in bays:
        reach = math.hypot(bay.width_m, bay.depth_m) + FRONT_REACH_M
        if math.hypot(bay.origin[0] - centre[0], bay.origin[1] - centre[1]) > max_range_m + reach:
            continue
        yaw = bay.yaw_rad
        inward = np.array([math.cos(yaw), math.sin(yaw)])
        if float((centre[:2] - bay.origin) @ inward) >= 0:
            continue  # the camera is not in front of the bay (it would see the backs of its loads)
        across = np.array([math.sin(yaw), -math.cos(yaw)])
        axes = np.column_stack((across, inward))
        top = bay.levels_z_m[-1] + TOP_HEIGHT_M
        coarse = (sparse[:, :2] - bay.origin) @ axes  # a sixteenth of the points first: is the bay in view at all?
        if not _inside(coarse[:, 0], coarse[:, 1], sparse[:, 2], bay, top).any():
            continue
        uv = (points[:, :2] - bay.origin) @ axes
        u, v, z = uv[:, 0], uv[:, 1], points[:, 2]
        index = np.nonzero(_inside(u, v, z, bay, top))[0]
        if len(index) < settings.min_cells:
            continue
        clear = index[np.abs(u[index]) <= 0.5 * bay.width_m - upright_margin_m]  # uprights are not modelled
        keep = clear[:: max(1, -(-len(clear) // max_evidence_points))]
        behind = _through(centre, ray_dir, ray_range, bay, axes, top, upright_margin_m)
        behind = behind[:: max(1, -(-len(behind) // (max_evidence_points // 4)))]
        evidence[bay.key] = DepthEvidence((float(centre[0]), float(centre[1]), float(centre[2])),
                                          np.vstack([points[keep], behind]), stamp_ns)
        view = _BayPoints(u[index], v[index], z[index], border[index], noise[index], hidden[index])
        boxes += _bay_boxes(bay, view, settings, stamp_ns)
    return RackView(tuple(boxes), evidence)


def _occluded(depth_m: npt.NDArray[np.float32]) -> npt.NDArray[np.bool_]:
    """Pixels next to (beside or below) a pixel nearer by more than ``_OCCLUDER_M``: what they show may be partly
    hidden there (an object behind another, an upright, a load overhanging in front). A surface seen at a grazing
    angle (a carton's side) changes its depth gradually and is not taken for an occlusion."""
    far = np.where(depth_m > 0, depth_m, np.inf).astype(np.float32)
    kernel = np.ones((2, 3), np.uint8)  # this row and the one below, one column either side
    nearest = cv2.erode(far, kernel, anchor=(1, 0), borderType=cv2.BORDER_REPLICATE)
    with np.errstate(invalid="ignore"):
        return np.asarray(far - nearest > _OCCLUDER_M, dtype=np.bool_)


def _through(centre: FloatArray, direction: FloatArray, depth: FloatArray, bay: Bay, axes: FloatArray, top: float,
             margin_m: float) -> FloatArray:
    """Map points ``BEHIND_M`` behind the bay's back of the rays (``direction`` scaled so that optical depth is 1,
    ``depth`` their measured optical depth, inf for none) that enter its front opening (uprights left out) and meet
    nothing before the back."""
    v0 = float((centre[:2] - bay.origin) @ axes[:, 1])
    dv = direction[:, :2] @ axes[:, 1]
    with np.errstate(divide="ignore", invalid="ignore"):
        t_front = np.where(dv > 1e-9, -v0 / dv, np.inf)
        t_back = np.where(dv > 1e-9, (bay.depth_m + BEHIND_M - v0) / dv, np.inf)
    u0 = (centre[:2] - bay.origin) @ axes[:, 0] + t_front * (direction[:, :2] @ axes[:, 0])
    z0 = centre[2] + t_front * direction[:, 2]
    ok = (np.isfinite(t_back) & (t_front > 0) & (depth > t_back) & (np.abs(u0) <= 0.5 * bay.width_m - margin_m)
          & (z0 >= 0.0) & (z0 < top))
    return np.asarray(centre + direction[ok] * t_back[ok, None], np.float64).reshape(-1, 3)


def _inside(u: FloatArray, v: FloatArray, z: FloatArray, bay: Bay, top: float) -> npt.NDArray[np.bool_]:
    """Points (bay frame) in the bay's volume: its width, from ``FRONT_REACH_M`` before its front to its back,
    from the floor to ``top``."""
    return (np.abs(u) <= 0.5 * bay.width_m) & (v >= -FRONT_REACH_M) & (v <= bay.depth_m) & (z >= 0.0) & (z < top)


class _Grid(NamedTuple):
    cell_m: float
    edge_m: float
    pallet_height_m: float
    min_cells: int
    min_width_m: float
    pallet_width_m: float
    pallet_depth_m: float | None


class _BayPoints(NamedTuple):
    """Points of one bay in its frame, whether each came from the image border, its depth noise (metres), and
    whether a nearer surface beside or below may hide part of its object (:func:`_occluded`)."""

    u: FloatArray
    v: FloatArray
    z: FloatArray
    border: npt.NDArray[np.bool_]
    noise: FloatArray
    occluded: npt.NDArray[np.bool_]

    def take(self, mask: npt.NDArray[Any]) -> _BayPoints:
        return _BayPoints(*(a[mask] for a in self))


def _bay_boxes(bay: Bay, pts: _BayPoints, grid: _Grid, stamp_ns: int) -> list[BoxEstimate]:
    """Beams, pallets and loads of one bay."""
    out: list[BoxEstimate] = []
    margin = 0.03  # the uprights at the bay's sides (narrow fronts of their own otherwise)
    half = 0.5 * bay.width_m - margin
    pallet_depth = grid.pallet_depth_m or bay.depth_m / bay.deep - 0.15
    levels = bay.levels_z_m
    for level, z0 in enumerate(levels):
        if level > 0:
            band = ((pts.z > z0 - bay.beam_height_m - 0.03) & (pts.z < z0 + 0.02) & (pts.v > -0.05) & (pts.v < 0.15)
                    & (np.abs(pts.u) < half))
            if band.sum() >= grid.min_cells * 4 and not pts.border[band].any():
                out.append(_beam(bay, level, pts.take(band), stamp_ns))
        z1 = levels[level + 1] - bay.beam_height_m if level + 1 < len(levels) else z0 + TOP_HEIGHT_M
        slab = (pts.z > z0 + 0.015) & (pts.z < z1 - 0.015) & (np.abs(pts.u) < half) & (pts.v < bay.depth_m - 0.03)
        if slab.sum() < grid.min_cells:
            continue
        level_pts = pts.take(slab)
        for objects in _components(level_pts, -half, z0, grid, whole=False):
            top = z0 + grid.pallet_height_m
            band = objects.z < top
            pallet = objects.take(band)
            # a row of cells above the pallet's top holds points of both (depth noise): loads start above it, and
            # one reaching down to it stands on the pallet's top
            rest = objects.take(objects.z >= top + _SEAM_M)
            if len(pallet.u) >= grid.min_cells and not pallet.border.any() and np.ptp(pallet.u) >= (
                    0.85 * grid.pallet_width_m if _hidden(pallet) else 0.3):
                out.append(_box(bay, level, ObjectKind.PALLET, pallet, pallet_depth, 0.02, stamp_ns, len(out),
                                bottom=z0))
            parts = _components(rest, -half, z0, grid, whole=True) if len(rest.u) >= grid.min_cells else []
            for load in parts:
                front = float(np.percentile(load.v, 10))
                centred = 2.0 * (_slot_centre(front, bay) - front)  # centred on its pallet position
                on_pallet = len(pallet.u) > 0 and float(np.min(load.z)) < top + _SEAM_M + 0.01
                out.append(_box(bay, level, ObjectKind.LOAD, load, min(max(centred, 0.2), pallet_depth), 0.1,
                                stamp_ns, len(out), bottom=top if on_pallet else None))
    return out


def _slot_centre(front_v: float, bay: Bay) -> float:
    """Middle (v) of the pallet position a front face at ``front_v`` belongs to."""
    slot = bay.depth_m / bay.deep
    k = min(max(math.floor((front_v + 0.05) / slot), 0), bay.deep - 1)
    return (k + 0.5) * slot


def _cells(pts: _BayPoints, u0: float, z0: float, grid: _Grid
           ) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.bool_], FloatArray]:
    """Front-view grid of the points (rows up from ``z0``, columns across from ``u0``, one empty cell around):
    each point's flat cell index, the cells with points, and each cell's mean depth into the rack (NaN empty)."""
    col = ((pts.u - u0) / grid.cell_m).astype(np.int64)
    row = ((pts.z - z0) / grid.cell_m).astype(np.int64)
    shape = (int(row.max()) + 5, int(col.max()) + 5)
    flat = (row + 2) * shape[1] + col + 2
    count = np.bincount(flat, minlength=shape[0] * shape[1]).reshape(shape)
    total = np.bincount(flat, weights=pts.v, minlength=shape[0] * shape[1]).reshape(shape)
    filled = count >= 2
    return flat, filled, np.where(filled, total / np.maximum(count, 1), np.nan)


def _components(pts: _BayPoints, u0: float, z0: float, grid: _Grid, *, whole: bool) -> list[_BayPoints]:
    """The points of each object front: connected grid cells without depth jumps, large and wide enough (not an
    upright or a side face seen edge-on) and, if ``whole``, neither cut by the image border nor partly hidden."""
    flat, filled, mean_v = _cells(pts, u0, z0, grid)
    edge = np.zeros(filled.shape, bool)
    for dr, dc in ((0, 1), (1, 0), (0, -1), (-1, 0)):
        with np.errstate(invalid="ignore"):
            edge |= mean_v - np.roll(mean_v, (dr, dc), axis=(0, 1)) > grid.edge_m
    n, found = cv2.connectedComponents((filled & ~edge).astype(np.uint8), connectivity=4)
    labels = np.asarray(found, dtype=np.int64)
    point_label = _regrow(labels.ravel()[flat], flat, pts.v, labels, mean_v, grid.edge_m)
    sizes = np.bincount(labels.ravel(), minlength=n)
    cut = np.bincount(point_label, weights=pts.border, minlength=n) > 0
    parts = [pts.take(point_label == k) for k in range(1, n) if sizes[k] >= grid.min_cells and not (whole and cut[k])]
    return [part for part in parts if np.ptp(part.u) >= grid.min_width_m and not (whole and _hidden(part))]


def _regrow(point_label: npt.NDArray[np.int64], flat: npt.NDArray[np.int64], v: FloatArray,
            labels: npt.NDArray[np.int64], mean_v: FloatArray, edge_m: float) -> npt.NDArray[np.int64]:
    """Give the points of cells cut at a depth jump (an object's outermost cells, mixed with what lies behind) to
    the neighbouring component whose depth they share, so the object keeps its full extent."""
    out = point_label.copy()
    lost = np.nonzero(out == 0)[0]
    width = labels.shape[1]
    flat_labels, flat_v = labels.ravel(), mean_v.ravel()
    for step in (1, -1, width, -width):
        neighbour = flat[lost] + step
        take = (out[lost] == 0) & (flat_labels[neighbour] > 0) & (np.abs(v[lost] - flat_v[neighbour]) <= edge_m)
        out[lost[take]] = flat_labels[neighbour[take]]
    return out


def _hidden(pts: _BayPoints) -> bool:
    """Whether the object's front face borders on something nearer (its side faces, receding in depth, would
    border on what it stands on)."""
    front = float(np.percentile(pts.v, 10))
    return bool((pts.occluded & (pts.v < front + 0.1)).any())


def _to_map(bay: Bay, u: float, v: float) -> tuple[float, float]:
    c, s = math.cos(bay.yaw_rad), math.sin(bay.yaw_rad)
    return bay.origin[0] + u * s + v * c, bay.origin[1] - u * c + v * s


def _sigma_map(bay: Bay, sigma_u: float, sigma_v: float) -> tuple[float, float]:
    c, s = math.cos(bay.yaw_rad), math.sin(bay.yaw_rad)
    return math.hypot(sigma_u * s, sigma_v * c), math.hypot(sigma_u * c, sigma_v * s)


def _wrap(angle: float) -> float:
    return math.atan2(math.sin(angle), math.cos(angle))


def _extent(values: FloatArray) -> tuple[float, float]:
    """Ends of the interval the values fill evenly, from their 1st and 99th percentiles (robust to stray points)."""
    lo, hi = np.percentile(values, [1, 99])
    pad = (hi - lo) / 98.0
    return float(lo - pad), float(hi + pad)


def _box(bay: Bay, level: int, kind: ObjectKind, pts: _BayPoints, depth_m: float, depth_sigma_m: float,
         stamp_ns: int, serial: int, *, bottom: float | None = None) -> BoxEstimate:
    """A box whose front face the points are: extent across and up from the points, depth assumed."""
    u_lo, u_hi = _extent(pts.u)
    z_lo, z_hi = _extent(pts.z)
    if bottom is not None:
        z_lo = bottom
    front = float(np.percentile(pts.v, 10))
    noise = float(np.median(pts.noise))
    cx, cy = _to_map(bay, 0.5 * float(u_lo + u_hi), front + 0.5 * depth_m)
    sx, sy = _sigma_map(bay, 0.02, math.hypot(noise, depth_sigma_m))
    n = len(pts.u)
    return BoxEstimate(id=f"{bay.key}/{level}/{kind.value}{serial}", kind=kind,
                       centre=(cx, cy, 0.5 * float(z_lo + z_hi)),
                       size=(float(u_hi - u_lo), depth_m, float(z_hi - z_lo)), yaw_rad=_wrap(bay.yaw_rad - math.pi / 2),
                       sigma=(sx, sy, 0.02), sigma_yaw_rad=0.02 if kind is ObjectKind.PALLET else 0.1,
                       score=n / (n + 50.0), stamp_ns=stamp_ns, bay=bay.key, level=level)


def _beam(bay: Bay, level: int, pts: _BayPoints, stamp_ns: int) -> BoxEstimate:
    """The level's beam pair: the front beam's top from its points, spanning the bay's width and depth."""
    top = float(np.percentile(pts.z, 98))
    front = float(np.percentile(pts.v, 10))
    cx, cy = _to_map(bay, 0.0, front + 0.5 * bay.depth_m)
    noise = float(np.median(pts.noise))
    sx, sy = _sigma_map(bay, 0.02, math.hypot(noise, 0.02))
    return BoxEstimate(id=f"{bay.key}/{level}/beam", kind=ObjectKind.BEAM,
                       centre=(cx, cy, top - 0.5 * bay.beam_height_m),
                       size=(bay.width_m, bay.depth_m, bay.beam_height_m),
                       yaw_rad=_wrap(bay.yaw_rad - math.pi / 2), sigma=(sx, sy, 0.01), sigma_yaw_rad=0.01,
                       score=1.0, stamp_ns=stamp_ns, bay=bay.key, level=level)


def camera_moved(before: npt.NDArray[Any], after: npt.NDArray[Any], *, min_move_m: float, min_turn_rad: float) -> bool:
    """Whether a camera's pose (4x4, map from optical) moved at least ``min_move_m`` or turned at least
    ``min_turn_rad`` from ``before`` to ``after``: a frame from where the last one was taken shows nothing new."""
    shift = float(np.linalg.norm(np.asarray(after, float)[:3, 3] - np.asarray(before, float)[:3, 3]))
    rotation = np.asarray(before, float)[:3, :3].T @ np.asarray(after, float)[:3, :3]
    turn = math.acos(max(-1.0, min(1.0, 0.5 * (float(np.trace(rotation)) - 1.0))))
    return shift >= min_move_m or turn >= min_turn_rad

