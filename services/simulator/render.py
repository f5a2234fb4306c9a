"""Software rendering of box scenes through a pinhole camera: z-buffered convex faces.

Each visible box face is clipped to the near plane, projected, rasterised with
``cv2.fillConvexPoly`` into its bounding rectangle, and its exact per-pixel depth comes from the
face's plane, so depth is exact up to pixel coverage at face edges. The floor (z = 0) is an
analytic plane. Surfaces are shaded by a fixed light and textured procedurally per class, or
with photo crops per box where :class:`Textures` has them.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import cv2
import numpy as np
import numpy.typing as npt

from services.simulator.world import Boxes, FloatArray, ObjectClass

_SHIFT = 4
_LIGHT = np.array([0.35, 0.25, 0.9]) / np.linalg.norm([0.35, 0.25, 0.9])
# faces as cyclic corner indices (footprint corners 0..3 at the bottom, 4..7 on top), counter-clockwise
# seen from outside: corner 0 is the texture origin, 0->1 the s edge, 0->3 the t edge (up on the sides)
_FACES = np.array([[0, 1, 5, 4], [1, 2, 6, 5], [2, 3, 7, 6], [3, 0, 4, 7], [4, 5, 6, 7], [3, 2, 1, 0]])


class PinholeCamera(NamedTuple):
    """Intrinsics of an undistorted camera; pixel (u, v) has its centre at integer coordinates."""

    fx: float
    fy: float
    cx: float
    cy: float
    width: int
    height: int

    @classmethod
    def from_fov(cls, width: int, height: int, horizontal_fov_rad: float) -> PinholeCamera:
        """A camera of square pixels with the given horizontal field of view."""
        f = 0.5 * width / math.tan(0.5 * horizontal_fov_rad)
        return cls(f, f, 0.5 * (width - 1), 0.5 * (height - 1), width, height)

    def k(self) -> FloatArray:
        """The 3x3 intrinsic matrix."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])


class Textures(NamedTuple):
    """Photo textures: ``atlas`` (m, s, s, 3) float32 0..1 and, per :class:`ObjectClass` value, the
    atlas indices of that class's crops (a box uses crop ``box index mod count``)."""

    atlas: npt.NDArray[np.float32]
    by_class: dict[int, npt.NDArray[np.int64]]


class Rendered(NamedTuple):
    """``rgb`` (h, w, 3) uint8; ``depth_m`` (h, w) float32 optical-axis depth, +inf where nothing;
    ``kind`` (h, w) int8 :class:`ObjectClass` (-1 nothing, 0 floor); ``box`` (h, w) int64 box index
    (-1 floor or nothing)."""

    rgb: npt.NDArray[np.uint8]
    depth_m: npt.NDArray[np.float32]
    kind: npt.NDArray[np.int8]
    box: npt.NDArray[np.int64]


def box_corners(boxes: Boxes) -> FloatArray:
    """Corners (n, 8, 3): the footprint at the bottom (0..3, counter-clockwise), then on top (4..7)."""
    xy = boxes.corners_xy()
    bottom = np.concatenate([xy, np.repeat(boxes.z_m[:, None, 0:1], 4, axis=1)], axis=2)
    top = np.concatenate([xy, np.repeat(boxes.z_m[:, None, 1:2], 4, axis=1)], axis=2)
    return np.concatenate([bottom, top], axis=1)


def _clip_near(points: FloatArray, near: float) -> FloatArray:
    """Sutherland-Hodgman clip of a polygon (k, 3) in camera coordinates to z >= near."""
    out = []
    for i in range(len(points)):
        a, b = points[i], points[(i + 1) % len(points)]
        if a[2] >= near:
            out.append(a)
        if (a[2] >= near) != (b[2] >= near):
            out.append(a + (near - a[2]) / (b[2] - a[2]) * (b - a))
    return np.array(out).reshape(-1, 3)


def _procedural(kind: npt.NDArray[np.int8], s_m: FloatArray, t_m: FloatArray, seed: npt.NDArray[np.int64]
                ) -> FloatArray:
    """Brightness factor (n,) of class patterns at face coordinates ``s_m``, ``t_m`` (metres)."""
    factor = np.ones(len(kind))
    hole = ((np.mod(t_m, 0.075) < 0.03) & (np.abs(np.mod(s_m, 0.1) - 0.05) < 0.015))
    factor[(kind == ObjectClass.UPRIGHT) & hole] = 0.35
    wall = kind == ObjectClass.WALL
    factor[wall & (np.mod(s_m, 1.2) < 0.03)] = 0.75
    gate = kind == ObjectClass.GATE
    factor[gate & (np.mod(t_m, 0.3) < 0.05)] = 0.7
    pallet = kind == ObjectClass.PALLET
    gap = (np.mod(s_m, 0.4) > 0.3) & (t_m > 0.02) & (t_m < 0.12)
    factor[pallet & gap] = 0.25
    load = kind == ObjectClass.LOAD
    factor[load & (np.abs(np.mod(s_m + 0.05 * (seed % 7), 0.6) - 0.3) < 0.025)] = 1.15
    factor[load & (np.mod(t_m, 0.35) < 0.01)] = 0.7
    grain = np.sin(s_m * 91.0 + t_m * 37.0 + seed) * np.sin(s_m * 13.0 - t_m * 71.0)
    return factor * (1.0 + 0.06 * grain)


def render_boxes(boxes: Boxes, world_from_optical: FloatArray, camera: PinholeCamera, *, far_m: float = 30.0,
                 near_m: float = 0.05, textures: Textures | None = None) -> Rendered:
    """Render ``boxes`` and the floor as seen from an optical frame (x right, y down, z forward).

    Parameters
    ----------
    boxes : Boxes
        The scene.
    world_from_optical : (4, 4) float64
        Pose of the camera's optical frame in the world, metres.
    camera : PinholeCamera
        Intrinsics.
    far_m, near_m : float
        Boxes beyond ``far_m`` (horizontally) are culled; surfaces closer than ``near_m`` are clipped.
    textures : Textures, optional
        Photo crops for some classes; procedural textures otherwise.
    """
    h, w = camera.height, camera.width
    rot, centre = world_from_optical[:3, :3], world_from_optical[:3, 3]
    zbuf = np.full((h, w), np.inf, np.float32)
    face_id = np.full((h, w), -1, np.int64)
    rx = ((np.arange(w) - camera.cx) / camera.fx).astype(np.float32)
    ry = ((np.arange(h) - camera.cy) / camera.fy).astype(np.float32)
    reach = np.hypot(*boxes.size_xy.T) * 0.5 if len(boxes) else np.zeros(0)
    near = np.hypot(*(boxes.centre_xy - centre[:2]).T) < far_m + reach
    index = np.nonzero(near)[0]
    corners = box_corners(boxes.take(index))  # (m, 8, 3)
    cam = (corners - centre) @ rot  # camera coordinates
    faces = corners[:, _FACES]  # (m, 6, 4, 3)
    normals = np.cross(faces[:, :, 1] - faces[:, :, 0], faces[:, :, 3] - faces[:, :, 0])
    lengths = np.linalg.norm(normals, axis=-1, keepdims=True)
    normals = normals / np.where(lengths > 0, lengths, 1.0)
    visible = np.einsum("mfk,mfk->mf", normals, faces[:, :, 0] - centre) < -1e-9
    face_z = cam[:, _FACES, 2]
    visible &= (face_z > near_m).any(axis=2)
    # a face wholly in front of the near plane needs no clipping, and one whose projection lies over a pixel off
    # the image is left out before the loop (its bounds check would drop it: the margin covers rounding), which
    # is most faces of a wide scene seen through a narrow cube face; the images are the same
    in_front = np.all(face_z >= near_m, axis=2)
    with np.errstate(divide="ignore", invalid="ignore"):
        u = camera.fx * cam[:, _FACES, 0] / face_z + camera.cx
        v = camera.fy * cam[:, _FACES, 1] / face_z + camera.cy
    off_image = (u.max(axis=2) < -2.0) | (u.min(axis=2) > w + 1.0) | (v.max(axis=2) < -2.0) | (v.min(axis=2) > h + 1.0)
    visible &= ~(in_front & off_image)
    k = camera.k()
    for m_i, f_i in zip(*np.nonzero(visible), strict=True):
        poly = cam[m_i, _FACES[f_i]] if in_front[m_i, f_i] else _clip_near(cam[m_i, _FACES[f_i]], near_m)
        if len(poly) < 3:
            continue
        uv = (poly @ k.T)[:, :2] / poly[:, 2:3]
        x0, y0 = np.floor(uv.min(axis=0)).astype(int)
        x1, y1 = np.ceil(uv.max(axis=0)).astype(int)
        x0, y0, x1, y1 = max(x0, 0), max(y0, 0), min(x1, w - 1), min(y1, h - 1)
        if x1 < x0 or y1 < y0:
            continue
        mask = np.zeros((y1 - y0 + 1, x1 - x0 + 1), np.uint8)
        pts = np.round((uv - (x0, y0)) * (1 << _SHIFT)).astype(np.int32)
        cv2.fillConvexPoly(mask, pts, 1, cv2.LINE_8, _SHIFT)
        n_c = rot.T @ normals[m_i, f_i]
        d_c = float(n_c @ cam[m_i, _FACES[f_i][0]])
        denom = n_c[0] * rx[None, x0:x1 + 1] + n_c[1] * ry[y0:y1 + 1, None] + n_c[2]
        with np.errstate(divide="ignore", invalid="ignore"):
            z = d_c / denom
        roi = zbuf[y0:y1 + 1, x0:x1 + 1]
        update = (mask > 0) & (z < roi) & (z > near_m)
        roi[update] = z[update]
        face_id[y0:y1 + 1, x0:x1 + 1][update] = m_i * 6 + f_i
    # the floor
    ray_z = rot[2, 0] * rx[None, :] + rot[2, 1] * ry[:, None] + rot[2, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        floor_z = np.where(ray_z < -1e-6, -centre[2] / ray_z, np.inf).astype(np.float32)
    floor = floor_z < zbuf
    zbuf = np.where(floor, floor_z, zbuf)
    rgb, kind, box = _shade(boxes, index, faces, normals, face_id, floor, zbuf, rot, centre, rx, ry, textures)
    return Rendered(rgb, zbuf, kind, box)


def _shade(boxes: Boxes, index: npt.NDArray[np.intp], faces: FloatArray, normals: FloatArray,
           face_id: npt.NDArray[np.int64], floor: npt.NDArray[np.bool_], zbuf: npt.NDArray[np.float32],
           rot: FloatArray, centre: FloatArray, rx: npt.NDArray[np.float32], ry: npt.NDArray[np.float32],
           textures: Textures | None) -> tuple[npt.NDArray[np.uint8], npt.NDArray[np.int8], npt.NDArray[np.int64]]:
    h, w = zbuf.shape
    rgb = np.zeros((h, w, 3), np.float32)
    rgb[:] = (0.23, 0.24, 0.27)  # far background under the roof
    kind = np.full((h, w), -1, np.int8)
    box = np.full((h, w), -1, np.int64)
    rows, cols = np.nonzero(np.isfinite(zbuf))
    depth = zbuf[rows, cols]
    ray = np.stack([rx[cols] * depth, ry[rows] * depth, depth], axis=1)
    points = (centre + ray @ rot.T).astype(np.float32)  # world point of every finite pixel
    on_floor = floor[rows, cols]
    if on_floor.any():
        p = points[on_floor]
        grain = np.sin(p[:, 0] * 23.0 + np.sin(p[:, 1] * 7.0)) * np.sin(p[:, 1] * 19.0 - p[:, 0] * 3.0)
        tone = 0.6 + 0.04 * grain
        tone[(np.abs(np.mod(p[:, 0], 10.0) - 5.0) < 0.05)] *= 0.9
        rgb[rows[on_floor], cols[on_floor]] = tone[:, None] * np.array([0.95, 0.95, 0.92], np.float32)
        kind[rows[on_floor], cols[on_floor]] = ObjectClass.FLOOR
    on_face = ~on_floor
    if on_face.any():
        r_f, c_f, p = rows[on_face], cols[on_face], points[on_face]
        flat = faces.reshape(-1, 4, 3)
        e1, e2 = flat[:, 1] - flat[:, 0], flat[:, 3] - flat[:, 0]
        len1, len2 = np.linalg.norm(e1, axis=1), np.linalg.norm(e2, axis=1)
        u1 = (e1 / np.maximum(len1, 1e-9)[:, None]).astype(np.float32)
        u2 = (e2 / np.maximum(len2, 1e-9)[:, None]).astype(np.float32)
        o1 = np.einsum("fk,fk->f", flat[:, 0], u1).astype(np.float32)
        o2 = np.einsum("fk,fk->f", flat[:, 0], u2).astype(np.float32)
        light = (0.55 + 0.45 * np.clip(normals.reshape(-1, 3) @ _LIGHT, 0.0, 1.0)).astype(np.float32)
        fid = face_id[r_f, c_f]
        s_m = np.einsum("nk,nk->n", p, u1[fid]) - o1[fid]
        t_m = np.einsum("nk,nk->n", p, u2[fid]) - o2[fid]
        box_index = index[fid // 6]
        classes = boxes.kind[box_index]
        colour = boxes.colour[box_index].astype(np.float32) / 255.0
        colour *= _procedural(classes, s_m, t_m, box_index)[:, None].astype(np.float32)
        if textures is not None:
            side = fid % 6 < 4
            size = textures.atlas.shape[1] - 1
            for cls, crops in textures.by_class.items():
                use = (classes == cls) & side
                if use.any() and len(crops):
                    crop = crops[box_index[use] % len(crops)]
                    f_use = fid[use]
                    u = np.clip(s_m[use] / len1[f_use], 0, 1) * size
                    v = (1.0 - np.clip(t_m[use] / len2[f_use], 0, 1)) * size
                    colour[use] = textures.atlas[crop, v.astype(np.int64), u.astype(np.int64)]
        rgb[r_f, c_f] = np.clip(colour * light[fid, None], 0, 1)
        kind[r_f, c_f] = classes
        box[r_f, c_f] = box_index
    return (rgb * 255.0 + 0.5).astype(np.uint8), kind, box
