"""Occupancy maps of rack halls drawn the ways other sensors and tools draw them, with exact ground truth.

The 3-D world (:mod:`services.simulator.layout`) sliced at one height gives one picture of a
rack; real maps show others. This module draws a walled hall of back-to-back rack rows straight
into a 2-D occupancy grid in one of these styles (:class:`RackStyle`):

* ``solid``: each rack an occupied rectangle (a lidar at beam height sees a loaded rack as a wall;
  Gazebo / nav2 warehouse maps draw racks so);
* ``uprights``: only the upright posts, as dots, some missing;
* ``pallet_height``: a lidar at pallet height: uprights, a loaded bay as the pallet's face with
  unknown space behind it, an empty bay open through to the flue (where the back of a pallet on
  the other side may show), random loading;
* ``overhang``: as ``pallet_height`` with pallets standing 0.05-0.2 m out into the aisle;
* ``beams``: beams at lidar height: the front and back of every rack a line, unknown inside;
* ``mixed``: every rack section in one of the above, at random;
* ``depot``: no racks, pallets and stacks of boxes standing on open floor.

The whole hall may be turned by ``rotation_rad``. Ground truth codes are those of the simulator's
``labels.png`` (:class:`PlaceTruth`): the aisles between rack rows and the perimeter and cross aisles
are corridor, the crossings of an aisle with a cross aisle are junctions (not the L bends of the
perimeter aisle), rack footprints (flue included) are storage, a depot's floor is open area; 0
off free space. Every bay (one side of the flue) has a cell id.
"""

from __future__ import annotations

import enum
import math
from typing import NamedTuple

import numpy as np
import numpy.typing as npt

UPRIGHT_M = 0.1
FLUE_M = 0.2
WALL_M = 0.2
PALLET_M = (1.2, 0.8)


class RackStyle(enum.Enum):
    """How racks appear in the occupancy grid."""

    SOLID = "solid"
    UPRIGHTS = "uprights"
    PALLET_HEIGHT = "pallet_height"
    OVERHANG = "overhang"
    BEAMS = "beams"
    MIXED = "mixed"
    DEPOT = "depot"


class PlaceTruth(enum.IntEnum):
    """Ground-truth place codes (the simulator's ``labels.png`` codes)."""

    NONE = 0
    CORRIDOR = 1
    JUNCTION = 2
    STORAGE = 3
    OPEN_AREA = 5


class RackMap(NamedTuple):
    """A drawn hall, grid order (row 0 = lowest y), pixel coordinates x = column, y = row.

    Attributes
    ----------
    occupancy : (H, W) int8
        100 occupied, 0 free, -1 unknown.
    truth : (H, W) uint8
        :class:`PlaceTruth` code of every free cell, 0 elsewhere.
    cells : (H, W) int32
        Bay id (1..N) over each bay's footprint (one side of the flue), 0 elsewhere.
    junctions : (H, W) int32
        Cross-aisle junction id (1..J) over each junction's rectangle, 0 elsewhere.
    junctions_px : list of (x, y)
        Centres of the junctions, pixels (junction ``k`` is entry ``k - 1``).
    racks_px : (R, 4, 2) float64
        Corners of every rack section's footprint (one side of the flue, between cross aisles), pixels.
    pallets_px : (P, 4, 2) float64
        Corners of the pallets and box stacks standing on open floor, pixels.
    resolution_m : float
    """

    occupancy: npt.NDArray[np.int8]
    truth: npt.NDArray[np.uint8]
    cells: npt.NDArray[np.int32]
    junctions: npt.NDArray[np.int32]
    junctions_px: list[tuple[float, float]]
    racks_px: npt.NDArray[np.float64]
    pallets_px: npt.NDArray[np.float64]
    resolution_m: float


class _Canvas:
    """Rectangles given in hall metres (u along the rows, v across) drawn turned onto the grid."""

    def __init__(self, size_m: tuple[float, float], *, resolution_m: float, rotation_rad: float, margin_m: float):
        self.res = resolution_m
        c, s = math.cos(rotation_rad), math.sin(rotation_rad)
        self.rot = np.array([[c, -s], [s, c]])
        corners = np.array([[0, 0], [size_m[0], 0], [size_m[0], size_m[1]], [0, size_m[1]]]) @ self.rot.T
        self.offset = -corners.min(axis=0) + margin_m
        extent = corners.max(axis=0) - corners.min(axis=0) + 2 * margin_m
        self.shape = (math.ceil(extent[1] / resolution_m), math.ceil(extent[0] / resolution_m))

    def px(self, points_m: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        """(..., 2) hall metres -> (..., 2) pixel (x, y)."""
        out: npt.NDArray[np.float64] = (points_m @ self.rot.T + self.offset) / self.res
        return out

    def corners(self, u0: float, u1: float, v0: float, v1: float) -> npt.NDArray[np.float64]:
        return self.px(np.array([[u0, v0], [u1, v0], [u1, v1], [u0, v1]], dtype=np.float64))

    def fill(self, image: npt.NDArray[np.generic], rects: list[tuple[float, float, float, float]], value: int) -> None:
        """Fill axis-aligned hall rectangles [u0, u1) x [v0, v1) with ``value``: the pixels whose centre is inside."""
        h, w = image.shape[:2]
        for u0, u1, v0, v1 in rects:
            box = self.corners(u0, u1, v0, v1)
            c0, r0 = np.maximum(np.floor(box.min(axis=0) - 0.5).astype(int), 0)
            c1, r1 = np.minimum(np.ceil(box.max(axis=0) + 0.5).astype(int), [w, h])
            if c1 <= c0 or r1 <= r0:
                continue
            cc, rr = np.meshgrid(np.arange(c0, c1) + 0.5, np.arange(r0, r1) + 0.5)
            # pixel centre -> hall metres (inverse of px)
            x, y = cc * self.res - self.offset[0], rr * self.res - self.offset[1]
            u = self.rot[0, 0] * x + self.rot[1, 0] * y
            v = self.rot[0, 1] * x + self.rot[1, 1] * y
            inside = (u >= u0) & (u < u1) & (v >= v0) & (v < v1)
            image[r0:r1, c0:c1][inside] = value


class _Layout(NamedTuple):
    size_m: tuple[float, float]
    rows_v: list[float]  # back-to-back double rows: v of the first rack's front
    sections_u: list[tuple[float, float]]  # (u0, u1) upright centres of the first and last upright
    aisles: list[tuple[float, float]]  # (v0, v1) of every aisle incl. the perimeter ones
    cross: list[tuple[float, float]]  # (u0, u1) of every cross aisle incl. the perimeter ones
    pitch_m: float
    depth_m: float
    bays: int


def _layout(
    rng: np.random.Generator,
    *,
    n_double_rows: int,
    n_sections: int,
    bays_per_section: int,
    aisle_width_m: tuple[float, float],
    cross_aisle_width_m: tuple[float, float],
) -> _Layout:
    pitch = float(rng.uniform(2.6, 2.8))
    depth = float(rng.uniform(1.0, 1.2))
    aisle_w = rng.uniform(*aisle_width_m, n_double_rows + 1)
    cross_w = rng.uniform(*cross_aisle_width_m, n_sections + 1)
    sections, cross = [], []
    u = WALL_M
    for s in range(n_sections + 1):
        # rack footprints and cross aisles meet on the uprights' centres
        cross.append((u, u + float(cross_w[s])))
        u += float(cross_w[s])
        if s < n_sections:
            sections.append((u, u + bays_per_section * pitch))
            u += bays_per_section * pitch
    rows, aisles = [], []
    v = WALL_M
    for r in range(n_double_rows + 1):
        aisles.append((v, v + float(aisle_w[r])))
        v += float(aisle_w[r])
        if r < n_double_rows:
            rows.append(v)
            v += 2 * depth + FLUE_M
    return _Layout((u + WALL_M, v + WALL_M), rows, sections, aisles, cross, pitch, depth, bays_per_section)


_Rects = list[tuple[float, float, float, float]]


class _Draw(NamedTuple):
    occupied: _Rects
    unknown: _Rects
    free: _Rects  # free cells drawn over unknown (an empty bay seen through)


def _rack_section(
    rng: np.random.Generator,
    style: RackStyle,
    lay: _Layout,
    u_span: tuple[float, float],
    v_front: tuple[float, float],
    *,
    missing: float,
    load: float,
) -> _Draw:
    """Obstacles of one double row section: rack A front at v_front[0] facing down, rack B front at v_front[1]."""
    half = UPRIGHT_M / 2
    u0, u1 = u_span
    va, vb = v_front
    d = lay.depth_m
    # v lines of the uprights: front A, back A, back B, front B
    lines = [va, va + d, vb - d, vb]
    occ: _Rects = []
    unk: _Rects = []
    free: _Rects = []
    xs = [u0 + k * lay.pitch_m for k in range(lay.bays + 1)]
    if style is RackStyle.SOLID:
        occ += [(u0, u1, va, va + d), (u0, u1, vb - d, vb)]
        unk.append((u0, u1, va + d, vb - d))
        return _Draw(occ, unk, free)
    for ux in xs:
        for k, uv in enumerate(lines):
            inner = k in (1, 2)
            if rng.random() >= missing or (style is RackStyle.BEAMS and not inner):
                occ.append((ux - half, ux + half, uv - half, uv + half))
    if style is RackStyle.UPRIGHTS:
        return _Draw(occ, unk, free)
    if style is RackStyle.BEAMS:
        occ += [(u0, u1, va - 0.03, va + 0.03), (u0, u1, vb - 0.03, vb + 0.03)]
        unk.append((u0, u1, va + 0.03, vb - 0.03))
        return _Draw(occ, unk, free)
    # pallet height: each bay loaded or empty
    over = style is RackStyle.OVERHANG
    loaded = rng.random((lay.bays, 2)) < load
    for b in range(lay.bays):
        b0, b1 = xs[b] + half + 0.08, xs[b + 1] - half - 0.08
        for side in (0, 1):
            if not loaded[b, side]:
                continue
            stick = float(rng.uniform(0.05, 0.2)) if over else float(rng.uniform(-0.05, 0.05))
            if side == 0:  # rack A faces lower v
                face = va - stick
                occ.append((b0, b1, face, face + 0.08))
                unk.append((b0, b1, face + 0.08, va + d))
            else:
                face = vb + stick
                occ.append((b0, b1, face - 0.08, face))
                unk.append((b0, b1, vb - d, face - 0.08))
        flue = (va + d, vb - d)
        if loaded[b].all():
            unk.append((b0, b1, *flue))
        elif loaded[b].any():
            # seen from the empty side: the flue is open, the other pallet shows its back
            if loaded[b, 0]:
                occ.append((b0, b1, flue[0] - 0.08, flue[0]))
            else:
                occ.append((b0, b1, flue[1], flue[1] + 0.08))
    return _Draw(occ, unk, free)


def _depot(rng: np.random.Generator, size_m: tuple[float, float]) -> _Rects:
    """Pallets and stacks of boxes on open floor: loose pallets, blocks of pallets, box stacks."""
    out: _Rects = []
    w, h = size_m
    taken: _Rects = []

    def clear(r: tuple[float, float, float, float]) -> bool:
        return all(r[1] + 1.8 < t[0] or t[1] + 1.8 < r[0] or r[3] + 1.8 < t[2] or t[3] + 1.8 < r[2] for t in taken)

    for _ in range(400):
        kind = rng.random()
        if kind < 0.5:  # a loose pallet
            pw, ph = PALLET_M if rng.random() < 0.5 else PALLET_M[::-1]
        elif kind < 0.8:  # a block of pallets 2-4 x 1-3
            pw, ph = PALLET_M[0] * rng.integers(2, 5), PALLET_M[1] * rng.integers(1, 4)
        else:  # a box stack
            pw, ph = rng.uniform(0.4, 1.0), rng.uniform(0.4, 1.0)
        u, v = rng.uniform(WALL_M + 1.5, w - WALL_M - 1.5 - pw), rng.uniform(WALL_M + 1.5, h - WALL_M - 1.5 - ph)
        r = (float(u), float(u + pw), float(v), float(v + ph))
        if clear(r):
            taken.append(r)
            out.append(r)
        if len(out) >= max(6, int(w * h / 60)):
            break
    return out


def rack_hall_map(
    seed: int,
    *,
    style: RackStyle = RackStyle.SOLID,
    resolution_m: float = 0.05,
    rotation_rad: float = 0.0,
    n_double_rows: int = 4,
    n_sections: int = 2,
    bays_per_section: int = 8,
    aisle_width_m: tuple[float, float] = (2.8, 3.5),
    cross_aisle_width_m: tuple[float, float] = (3.2, 4.0),
    missing: float = 0.1,
    load: tuple[float, float] = (0.3, 0.9),
    margin_m: float = 1.0,
) -> RackMap:
    """A walled hall of back-to-back rack rows drawn in ``style`` (see the module docstring).

    Parameters
    ----------
    seed : int
        Seed of the random layout, missing uprights and loading.
    style : RackStyle
    resolution_m : float
        Metres per cell.
    rotation_rad : float
        The hall turned by this angle about the map's origin (counter-clockwise).
    n_double_rows, n_sections, bays_per_section : int
        Back-to-back double rows across the hall, sections along it (cut by cross aisles), bays a
        section (2.6-2.8 m pitch, racks 1.0-1.2 m deep, 0.2 m flue).
    aisle_width_m, cross_aisle_width_m : (float, float)
        Ranges of the aisle and cross-aisle widths (perimeter aisles included).
    missing : float
        Share of uprights not seen.
    load : (float, float)
        Range of the hall's share of loaded bays (``pallet_height``, ``overhang``, ``mixed``).
    margin_m : float
        Unknown border around the hall.

    Returns
    -------
    RackMap
    """
    if resolution_m <= 0 or n_double_rows < 1 or n_sections < 1 or bays_per_section < 1:
        raise ValueError("resolution_m, n_double_rows, n_sections and bays_per_section must be positive")
    rng = np.random.default_rng(seed)
    lay = _layout(
        rng,
        n_double_rows=n_double_rows,
        n_sections=n_sections,
        bays_per_section=bays_per_section,
        aisle_width_m=aisle_width_m,
        cross_aisle_width_m=cross_aisle_width_m,
    )
    w, h = lay.size_m
    canvas = _Canvas(lay.size_m, resolution_m=resolution_m, rotation_rad=rotation_rad, margin_m=margin_m)
    occ = np.full(canvas.shape, -1, dtype=np.int8)
    truth = np.zeros(canvas.shape, dtype=np.uint8)
    cells = np.zeros(canvas.shape, dtype=np.int32)
    junctions = np.zeros(canvas.shape, dtype=np.int32)
    canvas.fill(occ, [(0, w, 0, h)], 100)
    canvas.fill(occ, [(WALL_M, w - WALL_M, WALL_M, h - WALL_M)], 0)
    inner = (WALL_M, w - WALL_M, WALL_M, h - WALL_M)
    racks: list[npt.NDArray[np.float64]] = []
    pallets: _Rects = []
    centres: list[tuple[float, float]] = []
    if style is RackStyle.DEPOT:
        canvas.fill(truth, [inner], PlaceTruth.OPEN_AREA.value)
        pallets = _depot(rng, lay.size_m)
        canvas.fill(occ, pallets, 100)
    else:
        canvas.fill(truth, [inner], PlaceTruth.CORRIDOR.value)
        share = float(rng.uniform(*load))
        draws: list[_Draw] = []
        cell = 1
        for va in lay.rows_v:
            vb = va + 2 * lay.depth_m + FLUE_M
            for u0, u1 in lay.sections_u:
                canvas.fill(truth, [(u0, u1, va, vb)], PlaceTruth.STORAGE.value)
                racks.append(canvas.corners(u0, u1, va, va + lay.depth_m))
                racks.append(canvas.corners(u0, u1, vb - lay.depth_m, vb))
                for b in range(lay.bays):
                    x0 = u0 + b * lay.pitch_m
                    canvas.fill(cells, [(x0, x0 + lay.pitch_m, va, va + lay.depth_m)], cell)
                    canvas.fill(cells, [(x0, x0 + lay.pitch_m, vb - lay.depth_m, vb)], cell + 1)
                    cell += 2
                kind = style
                if style is RackStyle.MIXED:
                    choices = [s for s in RackStyle if s not in (RackStyle.MIXED, RackStyle.DEPOT)]
                    kind = choices[int(rng.integers(len(choices)))]
                draws.append(_rack_section(rng, kind, lay, (u0, u1), (va, vb), missing=missing, load=share))
        k = 1
        for i, (c0, c1) in enumerate(lay.cross):
            for j, (a0, a1) in enumerate(lay.aisles):
                if i in (0, len(lay.cross) - 1) and j in (0, len(lay.aisles) - 1):
                    continue  # an L bend of the perimeter aisle
                canvas.fill(truth, [(c0, c1, a0, a1)], PlaceTruth.JUNCTION.value)
                canvas.fill(junctions, [(c0, c1, a0, a1)], k)
                cx, cy = canvas.px(np.array([(c0 + c1) / 2, (a0 + a1) / 2]))
                centres.append((float(cx), float(cy)))
                k += 1
        canvas.fill(occ, [r for dr in draws for r in dr.unknown], -1)
        canvas.fill(occ, [r for dr in draws for r in dr.free], 0)
        canvas.fill(occ, [r for dr in draws for r in dr.occupied], 100)
    truth[occ != 0] = 0
    cells[occ != 0] = 0
    pallet_px = np.array([canvas.corners(*r) for r in pallets]).reshape(-1, 4, 2)
    rack_px = np.array(racks, dtype=np.float64).reshape(-1, 4, 2)
    return RackMap(occ, truth, cells, junctions, centres, rack_px, pallet_px, resolution_m)
