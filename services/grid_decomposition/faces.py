"""Per-face geometry: bounding rectangle and how many of its corners stand on obstacles."""

from __future__ import annotations

from typing import NamedTuple

import cv2
import numpy as np
import numpy.typing as npt
from scipy import ndimage


class FaceGeometry(NamedTuple):
    """Geometry of every face, index 0 unused.

    Attributes
    ----------
    short_m, long_m : (F + 1,) float64
        Sides of the minimum-area rectangle around the face, metres.
    corners_on_obstacle : (F + 1,) int64
        How many of that rectangle's four corners lie within the tolerance of an obstacle.
    walled_fraction : (F + 1,) float64
        Fraction of the face's outline within 0.1 m (at least 2 px) of an obstacle (a pallet cell between uprights
        is open on all sides, a passage between solid blocks is walled along its length).
    centroid_px : (F + 1, 2) float64
        Centroid, (x = column, y = row).
    """

    short_m: npt.NDArray[np.float64]
    long_m: npt.NDArray[np.float64]
    corners_on_obstacle: npt.NDArray[np.int64]
    walled_fraction: npt.NDArray[np.float64]
    centroid_px: npt.NDArray[np.float64]


def face_geometry(
    face_image: npt.NDArray[np.int32],
    n_faces: int,
    obstacle: npt.NDArray[np.bool_],
    *,
    resolution_m: float,
    corner_tolerance_m: float = 0.25,
) -> FaceGeometry:
    """Minimum-area rectangles of faces and obstacles at their corners (rack uprights)."""
    n = n_faces + 1
    short = np.zeros(n)
    long = np.zeros(n)
    corners = np.zeros(n, dtype=np.int64)
    centroid = np.zeros((n, 2))
    walled = np.zeros(n)
    t = max(2, round(0.1 / resolution_m))
    touch = cv2.dilate(obstacle.astype(np.uint8), cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * t + 1,) * 2)) > 0
    r = max(1, round(corner_tolerance_m / resolution_m))
    near = cv2.dilate(obstacle.astype(np.uint8), cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * r + 1,) * 2)) > 0
    h, w = face_image.shape
    for fid, box in enumerate(ndimage.find_objects(face_image, max_label=n_faces), start=1):
        if box is None:
            continue
        mask = (face_image[box] == fid).astype(np.uint8)
        m = cv2.moments(mask, binaryImage=True)
        if m["m00"] > 0:
            centroid[fid] = (box[1].start + m["m10"] / m["m00"], box[0].start + m["m01"] / m["m00"])
        contours, _ = cv2.findContours(mask, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
        outline = np.concatenate(contours).reshape(-1, 2) + np.array([box[1].start, box[0].start])
        walled[fid] = float(touch[outline[:, 1], outline[:, 0]].mean())
        pts = outline.astype(np.float32)
        rect = cv2.minAreaRect(pts)
        (sw, sh) = rect[1]
        short[fid] = (min(sw, sh) + 1) * resolution_m
        long[fid] = (max(sw, sh) + 1) * resolution_m
        box_pts = np.rint(cv2.boxPoints(rect)).astype(np.int64)
        cx = box_pts[:, 0].clip(0, w - 1)
        cy = box_pts[:, 1].clip(0, h - 1)
        corners[fid] = int(near[cy, cx].sum())
    return FaceGeometry(short, long, corners, walled, centroid)
