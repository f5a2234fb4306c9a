"""Build a :class:`World` from a layout mapping (read from YAML).

A layout describes a hall (a rectangle ``hall: {length_m, width_m}`` or an ``outline`` polygon),
gates cut into its walls, rack blocks, open areas, rooms, chargers and actors::

    name: demo
    hall: {length_m: 40, width_m: 25}
    gates: [{id: G1, kind: dock, edge: 0, offset_m: 6, width_m: 3}]
    blocks:
      - {id: A, origin_m: [4, 4], yaw_rad: 0.0, aisles: 3, bays: 10, aisle_width_m: 3.0,
         bay_pitch_m: 2.7, rack_depth_m: 1.1, levels: 4, level_pitch_m: 1.5, fill: 0.7,
         cross_aisle_every: 5, cross_aisle_width_m: 3.0, end_corridor_m: 3.0}
    open_areas: [{id: staging, polygon: [[0, 0], [40, 0], [40, 4], [0, 4]]}]
    chargers: [{id: C1, pose: [1.0, 12.0, 3.14159]}]
    actors: [{id: F1, kind: forklift, path: [[2, 2], [30, 2]], speed_mps: 1.2}]
    seed: 0

A block's rows run along its own u axis (rotated by ``yaw_rad`` about ``origin_m``, its corner at
the back of the first row): a single row, then aisle, back-to-back double row, aisle, ..., and a
single row; every aisle is flanked by two rows facing it. Bays are numbered odd on the left
(lower-v) row of an aisle and even on the right, bins ``AA-BBB-LL`` (aisle, bay, level; level 01
is the floor). A block with a ``loads`` mapping fills its bins with random pallets and cartons and records their
ground truth (:mod:`services.simulator.loads`).
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Mapping, Sequence
from typing import Any, NamedTuple

import cv2
import numpy as np

from services.simulator.errors import SimulatorError
from services.simulator.loads import BinFrame, LoadOptions, fill_bin
from services.simulator.world import (
    Actor,
    ActorKind,
    Area,
    AreaKind,
    Bin,
    Boxes,
    Charger,
    FloatArray,
    Gate,
    LoadTruth,
    ObjectClass,
    RackRow,
    Uprights,
    World,
    concat_boxes,
)

_SIDES = {"south": 0, "east": 1, "north": 2, "west": 3}
_UPRIGHT_SIZE_M = (0.10, 0.08)
_BEAM_HEIGHT_M = 0.12
_BEAM_DEPTH_M = 0.05
_PALLET_HEIGHT_M = 0.15
_VNA_WIDTH_M = 2.0
_COLOURS = {
    ObjectClass.WALL: (200, 200, 195),
    ObjectClass.UPRIGHT: (20, 80, 200),
    ObjectClass.BEAM: (240, 110, 20),
    ObjectClass.PALLET: (170, 130, 80),
    ObjectClass.LOAD: (190, 160, 110),
    ObjectClass.GATE: (90, 110, 130),
    ObjectClass.CHARGER: (30, 160, 60),
}


class _BoxList:
    """Collects boxes one by one, then hands them over as :class:`Boxes`."""

    def __init__(self) -> None:
        self.rows: list[tuple[float, ...]] = []
        self.kinds: list[int] = []
        self.colours: list[tuple[int, int, int]] = []

    def add(self, centre: Sequence[float] | FloatArray, z: tuple[float, float], size: tuple[float, float], yaw: float,
            kind: ObjectClass, colour: tuple[int, int, int] | None = None) -> None:
        self.rows.append((float(centre[0]), float(centre[1]), z[0], z[1], size[0], size[1], yaw))
        self.kinds.append(int(kind))
        self.colours.append(colour or _COLOURS[kind])

    def boxes(self) -> Boxes:
        a = np.array(self.rows, dtype=np.float64).reshape(-1, 7)
        return Boxes(a[:, 0:2].copy(), a[:, 2:4].copy(), a[:, 4:6].copy(), a[:, 6].copy(),
                     np.array(self.kinds, np.int8), np.array(self.colours, np.uint8).reshape(-1, 3))


def _number(spec: Mapping[str, Any], key: str, default: float | None = None, *, where: str,
            minimum: float = 0.0, strict: bool = True) -> float:
    value = spec.get(key, default)
    if value is None:
        raise SimulatorError(f"{where}: missing {key!r}")
    try:
        number = float(value)
    except (TypeError, ValueError) as err:
        raise SimulatorError(f"{where}: {key} must be a number, got {value!r}") from err
    if not math.isfinite(number) or number < minimum or (strict and number == minimum):
        bound = ">" if strict else ">="
        raise SimulatorError(f"{where}: {key} must be finite and {bound} {minimum}, got {value!r}")
    return number


def _points(value: Any, *, where: str, minimum: int) -> FloatArray:
    try:
        points = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as err:
        raise SimulatorError(f"{where}: expected a list of [x, y] points, got {value!r}") from err
    if points.ndim != 2 or points.shape[1] != 2 or len(points) < minimum or not np.isfinite(points).all():
        raise SimulatorError(f"{where}: expected at least {minimum} finite [x, y] points, got {value!r}")
    return points


def _ccw(polygon: FloatArray) -> FloatArray:
    x, y = polygon[:, 0], polygon[:, 1]
    area = 0.5 * float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))
    return polygon if area > 0 else np.ascontiguousarray(polygon[::-1])


class _Frame(NamedTuple):
    """A block's (u, v) frame in the map."""

    origin: FloatArray
    yaw: float

    def point(self, u: float, v: float) -> FloatArray:
        c, s = math.cos(self.yaw), math.sin(self.yaw)
        return np.asarray(self.origin + np.array([c * u - s * v, s * u + c * v]), np.float64)

    def rect(self, u0: float, u1: float, v0: float, v1: float) -> FloatArray:
        return np.array([self.point(u0, v0), self.point(u1, v0), self.point(u1, v1), self.point(u0, v1)])


def _edge_walls(a: FloatArray, b: FloatArray, gaps: list[tuple[float, float]], *, thickness_m: float,
                height_m: float, out: _BoxList, segments: list[FloatArray]) -> None:
    """Wall boxes along edge a->b on its right-hand (outer, for a ccw polygon) side, leaving gaps."""
    length = float(np.hypot(*(b - a)))
    direction = (b - a) / length
    outward = np.array([direction[1], -direction[0]])
    yaw = math.atan2(direction[1], direction[0])
    cuts = [(-thickness_m, -thickness_m), *sorted(gaps), (length + thickness_m, length + thickness_m)]
    for (_, start), (end, _) in itertools.pairwise(cuts):
        if end - start <= 1e-6:
            continue
        mid = a + direction * 0.5 * (start + end) + outward * 0.5 * thickness_m
        out.add(mid, (0.0, height_m), (end - start, thickness_m), yaw, ObjectClass.WALL)
        s0, s1 = max(start, 0.0), min(end, length)
        if s1 > s0:
            segments.append(np.array([a + direction * s0, a + direction * s1]))


class _Built(NamedTuple):
    rows: list[RackRow]
    areas: list[Area]
    bins: list[Bin]
    uprights: list[tuple[float, float, str, int]]
    loads: list[LoadTruth]


def _transverse(frame: _Frame, u0: float, u1: float, bands: list[tuple[float, float]], v_total: float,
                name: str, areas: list[Area]) -> None:
    """A corridor across the block at u in [u0, u1], junctions where it meets the aisle ``bands``."""
    v = 0.0
    for i, (a0, a1) in enumerate(bands):
        if a0 > v + 1e-9:
            areas.append(Area(f"{name}-{i}", AreaKind.CORRIDOR, frame.rect(u0, u1, v, a0),
                              {"corridor_kind": "cross_aisle", "width_m": u1 - u0}))
        areas.append(Area(f"{name}-J{i}", AreaKind.JUNCTION, frame.rect(u0, u1, a0, a1), {}))
        v = a1
    if v_total > v + 1e-9:
        areas.append(Area(f"{name}-{len(bands)}", AreaKind.CORRIDOR, frame.rect(u0, u1, v, v_total),
                          {"corridor_kind": "cross_aisle", "width_m": u1 - u0}))


def _block(spec: Mapping[str, Any], *, first_aisle: int, row_offset: int, rng: np.random.Generator,
           boxes: _BoxList) -> _Built:
    """Rows, uprights, beams, pallets, bins and floor areas of one rack block."""
    name = str(spec.get("id", f"block{first_aisle}"))
    where = f"block {name}"
    origin = _points([spec.get("origin_m", [0.0, 0.0])], where=f"{where} origin_m", minimum=1)[0]
    frame = _Frame(origin, _number(spec, "yaw_rad", 0.0, where=where, minimum=-1e9))
    n_aisles = int(_number(spec, "aisles", 2, where=where))
    bays = int(_number(spec, "bays", 10, where=where))
    width = _number(spec, "aisle_width_m", 3.0, where=where)
    pitch = _number(spec, "bay_pitch_m", 2.7, where=where, minimum=0.5)
    depth = _number(spec, "rack_depth_m", 1.1, where=where, minimum=0.3)
    flue = _number(spec, "flue_m", 0.2, where=where, strict=False)
    levels = int(_number(spec, "levels", 4, where=where))
    level_pitch = _number(spec, "level_pitch_m", 1.5, where=where, minimum=0.5)
    fill = _number(spec, "fill", 0.7, where=where, strict=False)
    every = int(_number(spec, "cross_aisle_every", 0, where=where, strict=False)) or bays
    cross = _number(spec, "cross_aisle_width_m", 3.0, where=where)
    end = _number(spec, "end_corridor_m", 3.0, where=where, strict=False)
    if fill > 1:
        raise SimulatorError(f"{where}: fill must be in [0, 1], got {fill}")
    segments = [(s * (every * pitch + cross), min(every, bays - s * every)) for s in range(-(-bays // every))]
    length = segments[-1][0] + segments[-1][1] * pitch
    kind = "vna" if width < _VNA_WIDTH_M else "aisle"
    built = _Built([], [], [], [], [])
    loads = None if spec.get("loads") is None else LoadOptions.from_spec(spec["loads"], where=where)
    load_rng = np.random.default_rng(0 if loads is None else loads.seed)
    # v bands: (v0, v1, aisle index, facing +1 up / -1 down) per row; aisle bands
    rows: list[tuple[float, float, int, int]] = []
    aisle_bands: list[tuple[float, float]] = []
    v = 0.0
    for i in range(n_aisles):
        rows.append((v, v + depth, i, +1))
        v += depth
        aisle_bands.append((v, v + width))
        v += width
        rows.append((v, v + depth, i, -1))
        v += depth + flue
    v_total = v - flue
    up_height = levels * level_pitch + 0.3
    for (v0, v1, i, facing) in rows:
        aisle_no = first_aisle + i
        side = "L" if facing > 0 else "R"
        row_id = f"R{aisle_no:02d}{side}"
        row_index = row_offset + len(built.rows)
        front_v, back_v = (v1, v0) if facing > 0 else (v0, v1)
        front_yaw = frame.yaw + (math.pi / 2 if facing > 0 else -math.pi / 2)
        built.rows.append(RackRow(row_id, aisle_no, frame.rect(0.0, length, v0, v1), front_yaw, bays, levels))
        built.areas.append(Area(row_id, AreaKind.STORAGE, frame.rect(0.0, length, v0, v1), {"row": row_id}))
        access_v = 0.5 * (aisle_bands[i][0] + aisle_bands[i][1])
        bay_no = 1 if facing > 0 else 2
        for s_u, s_bays in segments:
            for j in range(s_bays + 1):
                u = min(max(s_u + j * pitch, s_u + 0.5 * _UPRIGHT_SIZE_M[0]), s_u + s_bays * pitch - 0.05)
                for tag, vv in (("F", front_v), ("B", back_v)):
                    inset = 0.5 * _UPRIGHT_SIZE_M[1] * (1 if vv == v0 else -1)
                    xy = frame.point(u, vv + inset)
                    built.uprights.append((xy[0], xy[1], f"{row_id}-{round(s_u / pitch) + j:03d}{tag}",
                                           row_index))
                    boxes.add(xy, (0.0, up_height), _UPRIGHT_SIZE_M, frame.yaw, ObjectClass.UPRIGHT)
            u_mid = s_u + 0.5 * s_bays * pitch
            for level in range(1, levels):
                z = level * level_pitch
                for vv in (front_v, back_v):
                    inset = 0.5 * _BEAM_DEPTH_M * (1 if vv == v0 else -1)
                    boxes.add(frame.point(u_mid, vv + inset), (z - _BEAM_HEIGHT_M, z),
                              (s_bays * pitch, _BEAM_DEPTH_M), frame.yaw, ObjectClass.BEAM)
            for j in range(s_bays):
                u0, u1 = s_u + j * pitch, s_u + (j + 1) * pitch
                access = frame.point(0.5 * (u0 + u1), access_v)
                for level in range(levels):
                    occupied = bool(rng.random() < fill)
                    z = level * level_pitch
                    built.bins.append(Bin(f"{aisle_no:02d}-{bay_no:03d}-{level + 1:02d}", row_id, aisle_no, bay_no,
                                          level + 1, frame.rect(u0, u1, v0, v1), z,
                                          (float(access[0]), float(access[1]),
                                           math.atan2(math.sin(front_yaw + math.pi), math.cos(front_yaw + math.pi))),
                                          occupied))
                    if occupied and loads is not None:
                        where_bin = BinFrame(frame.point, frame.yaw, u0, pitch, front_v, -float(facing), v1 - v0, z,
                                             level_pitch - _BEAM_HEIGHT_M)
                        built.loads.extend(fill_bin(built.bins[-1].id, where_bin, loads, load_rng, boxes))
                    elif occupied:
                        _pallets(frame, u0, pitch, v0, v1, z, level_pitch, rng, boxes)
                bay_no += 2
    u_ends = [(-end, 0.0), (length, length + end)] if end > 0 else []
    for s, (s_u, s_bays) in enumerate(segments):
        for i, (a0, a1) in enumerate(aisle_bands):
            start, stop = frame.point(s_u, 0.5 * (a0 + a1)), frame.point(s_u + s_bays * pitch, 0.5 * (a0 + a1))
            built.areas.append(Area(f"A{first_aisle + i:02d}-{s}", AreaKind.CORRIDOR,
                                    frame.rect(s_u, s_u + s_bays * pitch, a0, a1),
                                    {"corridor_kind": kind, "aisle": first_aisle + i, "width_m": width, "block": name,
                                     "start": start.tolist(), "end": stop.tolist()}))
        if s + 1 < len(segments):
            u_ends.append((s_u + s_bays * pitch, segments[s + 1][0]))
    for k, (u0, u1) in enumerate(u_ends):
        _transverse(frame, u0, u1, aisle_bands, v_total, f"{name}-X{k}", built.areas)
    return built


def _pallets(frame: _Frame, u0: float, pitch: float, v0: float, v1: float, z: float, level_pitch: float,
             rng: np.random.Generator, boxes: _BoxList) -> None:
    """Two pallets with loads in the bay starting at ``u0`` on the beam at height ``z``."""
    length = min(1.2, 0.5 * pitch - 0.15)
    deep = v1 - v0 - 0.1
    for centre_u in (u0 + 0.25 * pitch, u0 + 0.75 * pitch):
        centre = frame.point(centre_u, 0.5 * (v0 + v1))
        boxes.add(centre, (z, z + _PALLET_HEIGHT_M), (length, deep), frame.yaw, ObjectClass.PALLET)
        load_top = z + _PALLET_HEIGHT_M + float(rng.uniform(0.6, max(0.65, min(1.4, level_pitch - 0.45))))
        shade = int(rng.integers(-25, 25))
        colour = tuple(int(np.clip(c + shade, 0, 255)) for c in _COLOURS[ObjectClass.LOAD])
        boxes.add(centre, (z + _PALLET_HEIGHT_M, load_top), (length - 0.04, deep - 0.04), frame.yaw,
                  ObjectClass.LOAD, colour)  # type: ignore[arg-type]


def _gaps(gate_specs: Sequence[Mapping[str, Any]], outline: FloatArray, boxes: _BoxList
          ) -> tuple[dict[int, list[tuple[float, float]]], list[Gate]]:
    gaps: dict[int, list[tuple[float, float]]] = {}
    gates = []
    for k, spec in enumerate(gate_specs):
        gid = str(spec.get("id", f"G{k + 1}"))
        kind = str(spec.get("kind", "dock"))
        if kind not in ("dock", "door"):
            raise SimulatorError(f"gate {gid}: kind must be 'dock' or 'door', got {kind!r}")
        edge_spec = spec.get("edge", 0)
        edge = _SIDES.get(edge_spec, edge_spec) if isinstance(edge_spec, str) else edge_spec
        if not isinstance(edge, int) or not 0 <= edge < len(outline):
            raise SimulatorError(f"gate {gid}: edge must be 0..{len(outline) - 1} or a side name, got {edge_spec!r}")
        a, b = outline[edge], outline[(edge + 1) % len(outline)]
        length = float(np.hypot(*(b - a)))
        offset = _number(spec, "offset_m", where=f"gate {gid}", strict=False)
        width = _number(spec, "width_m", 3.0 if kind == "dock" else 1.0, where=f"gate {gid}")
        if offset + width > length:
            raise SimulatorError(f"gate {gid}: {offset} + {width} m runs past the {length:.2f} m edge {edge}")
        direction = (b - a) / length
        outward = np.array([direction[1], -direction[0]])
        gaps.setdefault(edge, []).append((offset, offset + width))
        p0, p1 = a + direction * offset, a + direction * (offset + width)
        gates.append(Gate(gid, kind, (float(p0[0]), float(p0[1])), (float(p1[0]), float(p1[1]))))
        recess = 0.5 if kind == "dock" else 0.3
        boxes.add(0.5 * (p0 + p1) + outward * (recess + 0.05), (0.0, 4.0 if kind == "dock" else 2.2),
                  (width + 0.2, 0.1), math.atan2(direction[1], direction[0]), ObjectClass.GATE)
    return gaps, gates


def world_from_layout(layout: Mapping[str, Any]) -> World:
    """The :class:`World` a layout mapping describes (see the module docstring for the format).

    Raises :class:`SimulatorError` naming the offending entry for missing or nonsensical values
    and for rack blocks that stick out of the hall.
    """
    if not isinstance(layout, Mapping):
        raise SimulatorError(f"a layout must be a mapping, got {type(layout).__name__}")
    name = str(layout.get("name", "warehouse"))
    if "outline" in layout:
        outline = _ccw(_points(layout["outline"], where="outline", minimum=3))
    else:
        hall = layout.get("hall")
        if not isinstance(hall, Mapping):
            raise SimulatorError("layout needs 'hall: {length_m, width_m}' or an 'outline' polygon")
        lx, ly = _number(hall, "length_m", where="hall"), _number(hall, "width_m", where="hall")
        outline = np.array([[0.0, 0.0], [lx, 0.0], [lx, ly], [0.0, ly]])
    rng = np.random.default_rng(int(layout.get("seed", 0)))
    thickness = _number(layout, "wall_thickness_m", 0.3, where="layout")
    height = _number(layout, "wall_height_m", 8.0, where="layout")
    boxes = _BoxList()
    gaps, gates = _gaps(layout.get("gates", []) or [], outline, boxes)
    wall_segments: list[FloatArray] = []
    for i in range(len(outline)):
        _edge_walls(outline[i], outline[(i + 1) % len(outline)], gaps.get(i, []), thickness_m=thickness,
                    height_m=height, out=boxes, segments=wall_segments)
    areas: list[Area] = []
    for kind, key in ((AreaKind.OPEN_AREA, "open_areas"), (AreaKind.ROOM, "rooms")):
        for k, spec in enumerate(layout.get(key, []) or []):
            aid = str(spec.get("id", f"{key}{k + 1}"))
            polygon = _ccw(_points(spec.get("polygon"), where=f"{key} {aid} polygon", minimum=3))
            areas.append(Area(aid, kind, polygon, {}))
            if kind is AreaKind.ROOM:
                a, b = polygon[0], polygon[1]
                mid = 0.5 * float(np.hypot(*(b - a)))
                for i in range(len(polygon)):
                    _edge_walls(polygon[(i + 1) % len(polygon)], polygon[i],
                                [(mid - 0.5, mid + 0.5)] if i == 0 else [], thickness_m=0.1, height_m=2.5,
                                out=boxes, segments=wall_segments)
    rows: list[RackRow] = []
    bins: list[Bin] = []
    uprights: list[tuple[float, float, str, int]] = []
    loads: list[LoadTruth] = []
    first_aisle = 1
    inside = outline.astype(np.float32).reshape(-1, 1, 2)
    for spec in layout.get("blocks", []) or []:
        built = _block(spec, first_aisle=first_aisle, row_offset=len(rows), rng=rng, boxes=boxes)
        for row in built.rows:
            for corner in row.polygon:
                if _inside(inside, corner) < -1e-6:
                    raise SimulatorError(f"block {spec.get('id')}: row {row.id} corner {corner.round(2).tolist()} "
                                         "lies outside the hall")
        first_aisle += max(1, len({r.aisle for r in built.rows}))
        rows += built.rows
        bins += built.bins
        areas += built.areas
        uprights += built.uprights
        loads += built.loads
    chargers = []
    for k, spec in enumerate(layout.get("chargers", []) or []):
        cid = str(spec.get("id", f"C{k + 1}"))
        pose = _points([spec.get("pose", [0, 0, 0])[:2]], where=f"charger {cid} pose", minimum=1)[0]
        yaw = float(spec.get("pose", [0, 0, 0])[2]) if len(spec.get("pose", [])) > 2 else 0.0
        chargers.append(Charger(cid, (float(pose[0]), float(pose[1]), yaw)))
        boxes.add(pose + 0.55 * np.array([math.cos(yaw), math.sin(yaw)]), (0.0, 1.0), (0.3, 0.6), yaw,
                  ObjectClass.CHARGER)
    actors = []
    for k, spec in enumerate(layout.get("actors", []) or []):
        aid = str(spec.get("id", f"actor{k + 1}"))
        try:
            actor_kind = ActorKind(spec.get("kind", "person"))
        except ValueError as err:
            raise SimulatorError(f"actor {aid}: kind must be one of {[a.value for a in ActorKind]}") from err
        actors.append(Actor(aid, actor_kind, _points(spec.get("path"), where=f"actor {aid} path", minimum=1),
                            _number(spec, "speed_mps", 1.0, where=f"actor {aid}", strict=False)))
    xy = np.array([(u[0], u[1]) for u in uprights], dtype=np.float64).reshape(-1, 2)
    return World(
        name=name,
        outline=outline,
        walls=np.array(wall_segments).reshape(-1, 2, 2),
        boxes=concat_boxes([boxes.boxes()]),
        uprights=Uprights(xy, tuple(u[2] for u in uprights), np.array([u[3] for u in uprights], np.int64)),
        rows=tuple(rows),
        areas=tuple(areas),
        bins=tuple(bins),
        gates=tuple(gates),
        chargers=tuple(chargers),
        actors=tuple(actors),
        layout=dict(layout),
        loads=tuple(loads),
    )


def _inside(contour: Any, point: FloatArray) -> float:
    """Signed distance of ``point`` to ``contour`` (positive inside), metres."""
    return float(cv2.pointPolygonTest(contour, (float(point[0]), float(point[1])), True))
