"""Per-face geometry: oriented bounding rectangle and how many of its corners stand on obstacles."""

from __future__ import annotations

from typing import NamedTuple

import cv2
import numpy as np
import numpy.typing as npt

from services.grid_decomposition.arrays import label_sums, nonzero_rc
from services.grid_decomposition.errors import DecompositionError


class FaceGeometry(NamedTuple):
    """Geometry of every face, index 0 unused.

    Attributes
    ----------
    short_m, long_m : (F + 1,) float64
        Sides of the face's bounding rectangle along its orientation, metres.
    corners_on_obstacle : (F + 1,) int64
        How many of that rectangle's four corners lie within the tolerance of an obstacle.
    ends_on_obstacle : (F + 1,) int64
        How many of the midpoints of its two short sides lie within the tolerance of an obstacle
        (a bay's short sides run between uprights and are open in the middle; a slice of a
        corridor between two cutting lines ends on the corridor's walls); -1 where the short
        sides are too short to tell (at most twice the tolerance: a flue between two racks).
    walled_fraction : (F + 1,) float64
        Fraction of the face's outline within 0.1 m (at least 2 px) of an obstacle (a pallet cell between uprights
        is open on all sides, a passage between solid blocks is walled along its length).
    centroid_px : (F + 1, 2) float64
        Centroid, (x = column, y = row).
    """

    short_m: npt.NDArray[np.float64]
    long_m: npt.NDArray[np.float64]
    corners_on_obstacle: npt.NDArray[np.int64]
    ends_on_obstacle: npt.NDArray[np.int64]
    walled_fraction: npt.NDArray[np.float64]
    centroid_px: npt.NDArray[np.float64]


def face_geometry(
    face_image: npt.NDArray[np.int32],
    n_faces: int,
    obstacle: npt.NDArray[np.bool_],
    *,
    resolution_m: float,
    face_angle_rad: npt.NDArray[np.float64] | None = None,
    corner_tolerance_m: float = 0.25,
) -> FaceGeometry:
    """Bounding rectangles of faces along their orientation and obstacles at their corners (uprights).

    All faces at once: the extremes of a face along two axes lie on its outline, so only outline
    pixels (a 4-neighbour in another face) are projected and reduced per face.

    Parameters
    ----------
    face_image : (H, W) int32
        Face id per pixel, 1..n_faces, 0 elsewhere.
    n_faces : int
    obstacle : (H, W) bool
    resolution_m : float
        Metres per pixel.
    face_angle_rad : (n_faces + 1,) float64, optional
        Direction of each face's rectangle (the lines that cut it), radians, x = column, y = row;
        default 0 (axis-aligned).
    corner_tolerance_m : float
        A corner within this distance of an obstacle stands on it.
    """
    n = n_faces + 1
    angle = np.zeros(n) if face_angle_rad is None else np.asarray(face_angle_rad, dtype=np.float64)
    if angle.shape != (n,):
        raise DecompositionError(f"face_angle_rad must have shape ({n},), got {angle.shape}")
    h, w = face_image.shape
    # outline pixels: a 4-neighbour differs (off the image counts as 0); each pair of neighbours compared once
    edge = np.ones((h, w), dtype=bool)
    edge[1:-1, 1:-1] = False
    across = face_image[:, 1:] != face_image[:, :-1]
    edge[:, 1:] |= across
    edge[:, :-1] |= across
    down = face_image[1:] != face_image[:-1]
    edge[1:] |= down
    edge[:-1] |= down
    edge &= face_image > 0
    count, sum_x, sum_y = label_sums(face_image, n)
    safe = np.maximum(count.astype(np.float64), 1.0)
    centroid = np.stack([sum_x / safe, sum_y / safe], axis=1)
    centroid[0] = 0.0
    oy, ox = nonzero_rc(edge)
    of = face_image[oy, ox].astype(np.int64)
    c, s = np.cos(angle), np.sin(angle)
    u = ox * c[of] + oy * s[of]
    v = -ox * s[of] + oy * c[of]
    lo_u, hi_u, lo_v, hi_v = (np.full(n, np.inf), np.full(n, -np.inf), np.full(n, np.inf), np.full(n, -np.inf))
    np.minimum.at(lo_u, of, u)
    np.maximum.at(hi_u, of, u)
    np.minimum.at(lo_v, of, v)
    np.maximum.at(hi_v, of, v)
    has = np.isfinite(lo_u)
    ext_u = np.where(has, hi_u - lo_u + 1.0, 0.0)
    ext_v = np.where(has, hi_v - lo_v + 1.0, 0.0)
    lo_u, hi_u, lo_v, hi_v = (np.where(has, e, 0.0) for e in (lo_u, hi_u, lo_v, hi_v))
    short = np.minimum(ext_u, ext_v) * resolution_m
    long = np.maximum(ext_u, ext_v) * resolution_m
    t = max(2, round(0.1 / resolution_m))
    touch = cv2.dilate(obstacle.astype(np.uint8), cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * t + 1,) * 2)) > 0
    n_out = np.bincount(of, minlength=n).astype(np.float64)
    walled = np.bincount(of, touch[oy, ox].astype(np.float64), n) / np.maximum(n_out, 1.0)
    r = max(1, round(corner_tolerance_m / resolution_m))
    near = cv2.dilate(obstacle.astype(np.uint8), cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * r + 1,) * 2)) > 0
    ids = np.flatnonzero(has)

    def on_obstacle(pu: npt.NDArray[np.float64], pv: npt.NDArray[np.float64]) -> npt.NDArray[np.bool_]:
        x = np.rint(pu[ids] * c[ids] - pv[ids] * s[ids]).astype(np.int64).clip(0, w - 1)
        y = np.rint(pu[ids] * s[ids] + pv[ids] * c[ids]).astype(np.int64).clip(0, h - 1)
        hit: npt.NDArray[np.bool_] = near[y, x]
        return hit

    corners = np.zeros(n, dtype=np.int64)
    for cu, cv in ((lo_u, lo_v), (lo_u, hi_v), (hi_u, lo_v), (hi_u, hi_v)):
        corners[ids] += on_obstacle(cu, cv)
    # short sides: at the ends of the long axis (v when u is the short extent)
    mid_u, mid_v = (lo_u + hi_u) / 2, (lo_v + hi_v) / 2
    u_short = ext_u <= ext_v
    ends = np.zeros(n, dtype=np.int64)
    for lo_end in (True, False):
        pu = np.where(u_short, mid_u, lo_u if lo_end else hi_u)
        pv = np.where(u_short, lo_v if lo_end else hi_v, mid_v)
        ends[ids] += on_obstacle(pu, pv)
    ends[np.minimum(ext_u, ext_v) <= 2 * r + 1] = -1
    return FaceGeometry(short, long, corners, ends, walled, centroid)
