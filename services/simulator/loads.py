"""Loaded racks: random pallets and cartons in the bins of a rack block, with exact ground truth.

A block of a layout with a ``loads`` mapping fills each occupied bin this way instead of the plain two
pallets with one load each::

    blocks:
      - {id: A, ..., rack_depth_m: 2.3, fill: 0.7,
         loads: {seed: 3, deep: 2, empty_slot: 0.25, bare: 0.1, stacked: 0.3, pair: 0.2, overhang: 0.05,
                 leaning: 0.04}}

Every bin has ``2 x deep`` pallet positions (two across the bay, ``deep`` one behind the other); an occupied bin
gets a pallet on at least one of them. A pallet carries nothing (``bare``), one carton, two cartons side by side
(``pair``), or a stack of two (``stacked``: the upper one smaller and set back, so its front face stands apart
in depth). A few single cartons in front positions overhang their pallet towards the aisle (``overhang``) or
lean: twisted and pushed so their centre is past the pallet's front edge (``leaning``; boxes cannot tilt in the
simulator, so "leaning" is a load that would tip). Every object is a box of :attr:`World.boxes`;
:class:`LoadTruth` records what it is, which bin it is in and what holds it up. Bins of blocks without
``loads`` come out exactly as before.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any, NamedTuple, Protocol

import cv2
import numpy as np

from services.simulator.errors import SimulatorError
from services.simulator.render import PinholeCamera, Rendered, box_corners
from services.simulator.world import FloatArray, LoadTruth, ObjectClass, World
from shared.bins import AccessPose, Bin

PALLET_HEIGHT_M = 0.15
PALLET_LENGTH_M = 1.2
"""Pallet size across the bay (the fork enters along its other side)."""
_GAP_M = 0.1
"""Clearance between the rack's front (or back) and a pallet, and between two pallets one behind the other."""
RACK_CAMERAS = ((0.6, 0.2), (2.4, 0.25))
"""(height_m, pitch_up_rad) of a mast's two rack-facing RGB-D cameras: from 2.6-3 m in front of the face of
:func:`loaded_layout`'s racks the low one sees levels 0 and 1 whole, the high one level 2."""
_LOAD_COLOUR = (190, 160, 110)
_PALLET_COLOUR = (170, 130, 80)


class LoadOptions(NamedTuple):
    """Probabilities of a block's ``loads`` mapping (see the module docstring) and its seed."""

    seed: int = 0
    deep: int = 1
    empty_slot: float = 0.25
    bare: float = 0.1
    stacked: float = 0.3
    pair: float = 0.2
    overhang: float = 0.05
    leaning: float = 0.04

    @classmethod
    def from_spec(cls, spec: Any, *, where: str) -> LoadOptions:
        """The options of a ``loads`` mapping; raises :class:`SimulatorError` naming a bad entry."""
        if not isinstance(spec, Mapping):
            raise SimulatorError(f"{where}: loads must be a mapping, got {spec!r}")
        unknown = set(spec) - set(cls._fields)
        if unknown:
            raise SimulatorError(f"{where}: unknown loads option(s) {sorted(unknown)}; known: {list(cls._fields)}")
        values: dict[str, Any] = {}
        for name, default in cls._field_defaults.items():
            value = spec.get(name, default)
            if isinstance(default, int):
                if not isinstance(value, int) or isinstance(value, bool):
                    raise SimulatorError(f"{where}: loads {name} must be an integer, got {value!r}")
            elif not isinstance(value, int | float) or not 0.0 <= float(value) <= 1.0:
                raise SimulatorError(f"{where}: loads {name} must be a probability in [0, 1], got {value!r}")
            values[name] = value
        if values["deep"] not in (1, 2):
            raise SimulatorError(f"{where}: loads deep must be 1 or 2, got {values['deep']!r}")
        if values["stacked"] + values["pair"] + values["bare"] > 1.0:
            raise SimulatorError(f"{where}: loads bare + stacked + pair must not exceed 1")
        return cls(**values)


class BoxSink(Protocol):
    """Where boxes go (the layout builder's box list)."""

    rows: list[tuple[float, ...]]

    def add(self, centre: Sequence[float] | FloatArray, z: tuple[float, float], size: tuple[float, float], yaw: float,
            kind: ObjectClass, colour: tuple[int, int, int] | None = None) -> None: ...


class BinFrame(NamedTuple):
    """Where a bin is: ``point(u, v)`` maps block coordinates to the map; the bin spans ``u0 .. u0 + pitch``
    across and ``front_v`` to ``front_v + inward * depth`` into the rack, its floor at ``z``."""

    point: Any
    yaw: float
    u0: float
    pitch: float
    front_v: float
    inward: float
    depth: float
    z: float
    headroom: float
    """Height free above the floor of the bin up to the next beam's underside (or a cap at the top level)."""


def fill_bin(bin_id: str, where: BinFrame, options: LoadOptions, rng: np.random.Generator, boxes: BoxSink
             ) -> list[LoadTruth]:
    """Pallets and loads of one occupied bin, added to ``boxes``; their ground truth."""
    deep = options.deep
    pallet_depth = (where.depth - _GAP_M * (deep + 1)) / deep
    length = min(PALLET_LENGTH_M, 0.5 * where.pitch - 0.15)
    filled = rng.random((2, deep)) >= options.empty_slot
    if not filled.any():
        filled[int(rng.integers(0, 2)), int(rng.integers(0, deep))] = True
    support = "floor" if where.z <= 1e-9 else "beam"
    truth: list[LoadTruth] = []
    for slot in range(2):
        for deep_slot in range(deep):
            if not filled[slot, deep_slot]:
                continue
            behind = bool(deep_slot > 0 and filled[slot, :deep_slot].any())
            u = where.u0 + (0.25 + 0.5 * slot) * where.pitch
            v = where.front_v + where.inward * (_GAP_M + (deep_slot + 0.5) * pallet_depth + deep_slot * _GAP_M)
            pallet_id = f"{bin_id}/P{slot}{deep_slot}"
            truth.append(_add(boxes, pallet_id, bin_id, ObjectClass.PALLET, where, (u, v), (0.0, PALLET_HEIGHT_M),
                              (length, pallet_depth), 0.0, support, slot, deep_slot, behind, _PALLET_COLOUR))
            truth += _loads(pallet_id, bin_id, where, (u, v), (length, pallet_depth), options, rng, boxes,
                            slot, deep_slot, behind)
    return truth


def _add(boxes: BoxSink, oid: str, bin_id: str, kind: ObjectClass, where: BinFrame, uv: tuple[float, float],
         z: tuple[float, float], size: tuple[float, float], yaw: float, support: str, slot: int, deep_slot: int,
         behind: bool, colour: tuple[int, int, int], *, stable: bool = True, overhang: bool = False) -> LoadTruth:
    index = len(boxes.rows)
    boxes.add(where.point(*uv), (where.z + z[0], where.z + z[1]), size, where.yaw + yaw, kind, colour)
    return LoadTruth(oid, bin_id, kind, index, support, slot, deep_slot, behind, stable, overhang)


def _shade(colour: tuple[int, int, int], delta: int) -> tuple[int, int, int]:
    r, g, b = (int(np.clip(c + delta, 0, 255)) for c in colour)
    return r, g, b


def _loads(pallet_id: str, bin_id: str, where: BinFrame, uv: tuple[float, float], pallet: tuple[float, float],
           options: LoadOptions, rng: np.random.Generator, boxes: BoxSink, slot: int, deep_slot: int,
           behind: bool) -> list[LoadTruth]:
    """The cartons on one pallet."""
    u, v = uv
    length, depth = pallet
    base = PALLET_HEIGHT_M
    room = max(0.3, where.headroom - base - 0.15)
    shade = int(rng.integers(-30, 30))
    colour = _shade(_LOAD_COLOUR, shade)
    draw = float(rng.random())
    common = (bin_id, ObjectClass.LOAD, where)
    if draw < options.bare:
        return []
    if draw < options.bare + options.stacked:
        h1 = float(rng.uniform(0.3, 0.55)) * room
        h2 = float(rng.uniform(0.25, 0.4)) * room
        w2 = float(rng.uniform(0.55, 0.85)) * length
        setback = float(rng.uniform(0.1, 0.2))
        lower = _add(boxes, f"{pallet_id}/L0", *common, (u, v), (base, base + h1), (length - 0.04, depth - 0.04),
                     0.0, pallet_id, slot, deep_slot, behind, colour)
        upper_colour = _shade(colour, -25)
        upper = _add(boxes, f"{pallet_id}/L1", *common, (u, v + where.inward * 0.5 * setback),
                     (base + h1, base + h1 + h2), (w2, depth - 0.04 - setback), 0.0, lower.id, slot, deep_slot,
                     behind, upper_colour)
        return [lower, upper]
    if draw < options.bare + options.stacked + options.pair:
        gap = float(rng.uniform(0.12, 0.2))
        width = 0.5 * (length - 0.04 - gap)
        out = []
        for k, side in enumerate((-1.0, 1.0)):
            height = float(rng.uniform(0.4, 0.9)) * room
            out.append(_add(boxes, f"{pallet_id}/L{k}", *common, (u + side * 0.5 * (width + gap), v),
                            (base, base + height), (width, depth - 0.04), 0.0, pallet_id, slot, deep_slot, behind,
                            colour))
        return out
    height = float(rng.uniform(0.45, 0.95)) * room
    size = (length - 0.04, depth - 0.04)
    shift_v, yaw, stable, overhang = 0.0, 0.0, True, False
    odd = float(rng.random()) if deep_slot == 0 else 1.0  # a back position's load cannot reach into the front one
    if odd < options.leaning:
        yaw = float(rng.uniform(0.1, 0.2)) * (1 if rng.random() < 0.5 else -1)
        size = (0.6 * length, 0.5 * depth)
        shift_v = -where.inward * (0.5 * depth + 0.05)  # its centre past the pallet's front edge: it would tip
        stable, overhang = False, True
    elif odd < options.leaning + options.overhang:
        shift_v = -where.inward * float(rng.uniform(0.15, 0.25))  # towards the aisle
        overhang = True
    return [_add(boxes, f"{pallet_id}/L0", *common, (u, v + shift_v), (base, base + height), size, yaw,
                 pallet_id, slot, deep_slot, behind, colour, stable=stable, overhang=overhang)]


def loaded_layout(seed: int, *, deep: int = 1, aisles: int = 2, bays: int = 6, levels: int = 3) -> dict[str, Any]:
    """A small hall whose racks hold random loads on every level (seeded), single- or double-deep.

    Two rows face each aisle; level 0 is the floor, the beams of the levels above are 1.3 m apart, so two
    rack-facing RGB-D views (:data:`RACK_CAMERAS`, :func:`rack_view`) see a bay's three levels from the aisle.
    """
    if deep not in (1, 2):
        raise SimulatorError(f"deep must be 1 or 2, got {deep}")
    depth = 1.1 if deep == 1 else 2.3
    width = 3.2
    span = aisles * (2 * depth + width + 0.2)
    return {
        "name": f"loaded-{seed}-{deep}",
        "hall": {"length_m": round(bays * 2.7 + 10.0, 3), "width_m": round(span + 8.0, 3)},
        "gates": [{"id": "G1", "kind": "dock", "edge": "south", "offset_m": 2.0, "width_m": 3.0}],
        "blocks": [{"id": "A", "origin_m": [5.0, 4.0], "aisles": aisles, "bays": bays, "aisle_width_m": width,
                    "bay_pitch_m": 2.7, "rack_depth_m": depth, "levels": levels, "level_pitch_m": 1.3, "fill": 0.7,
                    "end_corridor_m": 2.5, "loads": {"seed": seed, "deep": deep}}],
        "seed": seed,
    }


def rack_view(world: World, bin_id: str, *, standoff_m: float, height_m: float, pitch_up_rad: float = 0.0,
              along_m: float = 0.0) -> FloatArray:
    """Pose (4, 4) in the map of an optical frame (x right, y down, z forward) looking into a bin's bay.

    The camera stands ``standoff_m`` in front of the bay's opening (in the aisle), ``along_m`` to the right
    along the rack face, ``height_m`` above the floor, pitched up by ``pitch_up_rad`` (what a rack-facing
    camera at :func:`services.simulator.cameras.rack_rgbd_mount` sees when the robot stops at the bay).
    """
    record = next((b for b in world.bins if b.id == bin_id), None)
    if record is None:
        raise SimulatorError(f"no bin {bin_id!r} in world {world.name!r}")
    row = next(r for r in world.rows if r.id == record.row)
    out = np.array([math.cos(row.front_yaw_rad), math.sin(row.front_yaw_rad)])
    centre = record.polygon.mean(axis=0)
    edge = record.polygon - centre
    half_depth = float(np.max(edge @ out))
    right = np.array([out[1], -out[0]]) * -1.0  # right of someone looking into the rack (along -out)
    xy = centre + out * (half_depth + standoff_m) + right * along_m
    forward = np.array([-out[0], -out[1], 0.0]) * math.cos(pitch_up_rad) + np.array([0.0, 0.0, math.sin(pitch_up_rad)])
    down = -(np.array([out[0], out[1], 0.0]) * math.sin(pitch_up_rad) + np.array([0.0, 0.0, math.cos(pitch_up_rad)]))
    pose = np.eye(4)
    pose[:3, 0] = np.cross(down, forward)
    pose[:3, 1] = down
    pose[:3, 2] = forward
    pose[:3, 3] = (xy[0], xy[1], height_m)
    return pose


def bin_records(world: World) -> list[Bin]:
    """The world's bins as the pillar stage stores them (:class:`shared.bins.Bin`, ``level`` 0 the floor), each
    footprint starting with the front edge (left to right seen from the aisle)."""
    rows = {r.id: r for r in world.rows}
    out = []
    for b in world.bins:
        out_dir = np.array([math.cos(rows[b.row].front_yaw_rad), math.sin(rows[b.row].front_yaw_rad)])
        centre = b.polygon.mean(axis=0)
        front = np.argsort(-((b.polygon - centre) @ out_dir))[:2]  # the two corners nearest the aisle
        left, right = b.polygon[front]
        along = right - left
        if float(along[0] * out_dir[1] - along[1] * out_dir[0]) > 0:  # left first, seen from the aisle
            left, right = right, left
        back_right = right - 2 * float((right - centre) @ out_dir) * out_dir
        back_left = left - 2 * float((left - centre) @ out_dir) * out_dir
        ring = [left, right, back_right, back_left, left]
        out.append(Bin(id=b.id, centre=(float(centre[0]), float(centre[1])), aisle=b.aisle, bay=b.bay,
                       level=b.level - 1, z_m=b.z_m, footprint=tuple((float(x), float(y)) for x, y in ring),
                       access_pose=AccessPose(*b.access_pose), row=b.row))
    return out


def seen_whole(world: World, rendered: Rendered, world_from_optical: FloatArray, camera: PinholeCamera, *,
               min_fraction: float = 0.6, border_px: int = 4) -> list[LoadTruth]:
    """The loaded objects a rendered view shows (nearly) whole from the front: the camera stands on the aisle
    side of the object, its front face (the one towards the aisle) projects inside the image (``border_px`` from
    its edges) and at least ``min_fraction`` of that face's pixels show the object (not hidden behind others).

    ``rendered`` is :func:`services.simulator.render_boxes` of ``world.boxes`` (no actors) from ``world_from_optical``.
    """
    if not world.loads:
        return []
    rows = {r.id: r for r in world.rows}
    front_yaw = {b.id: rows[b.row].front_yaw_rad for b in world.bins}
    index = np.array([t.box for t in world.loads])
    boxes = world.boxes.take(index)
    corners = box_corners(boxes)  # (m, 8, 3): footprint corners 0..3 at the bottom, 4..7 on top
    origin = world_from_optical[:3, 3]
    cam = (corners - origin) @ world_from_optical[:3, :3]
    size = np.array([camera.width, camera.height])
    out = []
    for k, truth in enumerate(world.loads):
        out_dir = np.array([math.cos(front_yaw[truth.bin_id]), math.sin(front_yaw[truth.bin_id])])
        if float((origin[:2] - boxes.centre_xy[k]) @ out_dir) <= 0:
            continue
        foot = corners[k, :4, :2] - boxes.centre_xy[k]
        side = int(np.argmax([(foot[i] + foot[(i + 1) % 4]) @ out_dir for i in range(4)]))  # the aisle side
        face = cam[k, [side, (side + 1) % 4, 4 + (side + 1) % 4, 4 + side]]
        if (face[:, 2] <= 0.05).any():
            continue
        uv = np.column_stack((camera.fx * face[:, 0] / face[:, 2] + camera.cx,
                              camera.fy * face[:, 1] / face[:, 2] + camera.cy))
        if not ((uv >= border_px) & (uv < size - border_px)).all():
            continue
        mask = np.zeros((camera.height, camera.width), np.uint8)
        cv2.fillConvexPoly(mask, np.round(uv).astype(np.int32), 1)
        inside = mask > 0
        area = int(inside.sum())
        if area > 0 and int((rendered.box[inside] == truth.box).sum()) >= min_fraction * area:
            out.append(truth)
    return out
