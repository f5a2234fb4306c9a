"""Walls as the map draws them: each unit wall's own thickness and offset, fitted after the chain.

The seed's world (section 3.4) draws every wall as a band of one thickness along the border of its unit's
rectangle. A real map's walls vary: freiburg's are 0.2 m on average but thinner and thicker in places, a wall
drawn by a laser from one side lies off the band by a cell or two, g4s_y2 draws them blurred. Given the units
and doors, each of a unit's four walls gets its own **inner face** (moved into the unit by ``shift`` cells,
negative: outwards; the unit's free space reaches the inner face) and **thickness** (cells, from the inner face
outwards), where that beats a prior cost per wall drawn other than the default band. A door stays an opening
through its two walls at whatever thickness they are drawn.

A wall's best shape depends on its unit's other walls (the corners) and on its neighbours' walls, so the walls
are fitted by coordinate ascent (each wall the best given all the others, until none changes): a maximum of the
posterior over wall shapes for the given units, not necessarily the global one. The chain does not see them.
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import NamedTuple

import numpy as np
import numpy.typing as npt

from services.floor_plan.likelihood import CellClass
from services.floor_plan.world import Rect, Side, World, wall_band


class WallShape(NamedTuple):
    """One wall of a unit: its inner face moved ``shift`` cells into the unit (negative: outwards) and its
    ``thickness`` in cells, measured from the inner face outwards. The seed's band is ``(0, wall_cells)``."""

    shift: int
    thickness: int


class Walls(NamedTuple):
    """The world's rendering with fitted walls and the walls' shapes."""

    classes_world: npt.NDArray[np.uint8]
    """C_W (working frame) with every wall drawn as fitted; the fixed walls drawn as walls."""
    shapes: dict[int, tuple[WallShape, WallShape, WallShape, WallShape]]
    """Per unit id, its walls in :class:`~services.floor_plan.world.Side` order."""
    fitted: int
    """How many walls are drawn other than the seed's band."""


_Counts = tuple[npt.NDArray[np.int16], npt.NDArray[np.int16], npt.NDArray[np.int16]]


class _Faces(NamedTuple):
    """A unit's free space (inclusive rows a0..a1, columns b0..b1) and its walls' thicknesses."""

    a0: int
    a1: int
    b0: int
    b1: int
    w: tuple[int, int, int, int]


def _faces(rect: Rect, shapes: tuple[WallShape, ...], t: int) -> _Faces:
    top, bottom, left, right = shapes
    return _Faces(rect.r0 + t + top.shift, rect.r1 - t - bottom.shift, rect.c0 + t + left.shift,
                  rect.c1 - t - right.shift, (top.thickness, bottom.thickness, left.thickness, right.thickness))


def _band(f: _Faces, side: Side) -> Rect:
    """The cells of one wall (corners included: a wall runs along its unit's outer faces)."""
    wt, wb, wl, wr = f.w
    match side:
        case Side.TOP:
            return Rect(f.a0 - wt, f.a0 - 1, f.b0 - wl, f.b1 + wr)
        case Side.BOTTOM:
            return Rect(f.a1 + 1, f.a1 + wb, f.b0 - wl, f.b1 + wr)
        case Side.LEFT:
            return Rect(f.a0 - wt, f.a1 + wb, f.b0 - wl, f.b0 - 1)
        case _:
            return Rect(f.a0 - wt, f.a1 + wb, f.b1 + 1, f.b1 + wr)


def _door_cells(band: Rect, side: Side, door: Rect) -> Rect:
    """A door's opening through a wall band: the band over the door's extent along the wall."""
    if side in (Side.TOP, Side.BOTTOM):
        return band._replace(c0=door.c0, c1=door.c1)
    return band._replace(r0=door.r0, r1=door.r1)


def _parts(f: _Faces, doors: dict[Side, list[Rect]]) -> Iterator[tuple[int, Rect]]:
    """(count index, rect) of everything one unit draws: 0 free space, 1 walls, 2 door openings."""
    yield 0, Rect(f.a0, f.a1, f.b0, f.b1)
    for side in Side:
        band = _band(f, side)
        yield 1, band
        for d in doors.get(side, ()):
            yield 2, _door_cells(band, side, d)


def _add(counts: _Counts, f: _Faces, doors: dict[Side, list[Rect]], sign: int) -> None:
    for k, r in _parts(f, doors):
        if r.r0 <= r.r1 and r.c0 <= r.c1:
            counts[k][r.r0 : r.r1 + 1, r.c0 : r.c1 + 1] += sign


def _classes(n_int: npt.NDArray[np.integer], n_wall: npt.NDArray[np.integer], n_door: npt.NDArray[np.integer],
             fixed: npt.NDArray[np.bool_]) -> npt.NDArray[np.uint8]:
    wall = ((n_wall > 0) & (n_door == 0)) | fixed
    free = ~wall & ((n_int > 0) | (n_door > 0))
    out = np.where(wall, np.uint8(CellClass.WALL), np.where(free, np.uint8(CellClass.FREE),
                                                                np.uint8(CellClass.UNKNOWN)))
    return out.astype(np.uint8)


def _oriented(grid: npt.NDArray[np.generic], side: Side, face: int, k0: int, k1: int, j0: int,
              j1: int) -> npt.NDArray[np.generic]:
    """The window of ``grid`` at offsets ``k0..k1`` from ``face`` into the unit (rows of the result) and along
    the wall at ``j0..j1`` (columns of the result)."""
    match side:
        case Side.TOP:
            return grid[..., face + k0 : face + k1 + 1, j0 : j1 + 1]
        case Side.BOTTOM:
            return grid[..., face - k1 : face - k0 + 1, j0 : j1 + 1][..., ::-1, :]
        case Side.LEFT:
            return np.swapaxes(grid[..., j0 : j1 + 1, face + k0 : face + k1 + 1], -1, -2)
        case _:
            return np.swapaxes(grid[..., j0 : j1 + 1, face - k1 : face - k0 + 1][..., ::-1], -1, -2)


def fit_walls(
    world: World, classes_map: npt.NDArray[np.uint8], log_table: npt.NDArray[np.float64], *, wall_cells: int,
    fixed: npt.NDArray[np.bool_], max_shift: int, max_thickness: int, log_cost: float, passes: int = 4,
) -> Walls:
    """Fit every unit wall's inner face and thickness to the map, given the units and doors.

    Parameters
    ----------
    world : World
        Units and doors in cells of ``classes_map``'s grid.
    classes_map : (H, W) uint8
        C_M (:class:`~services.floor_plan.likelihood.CellClass`) in the world's grid.
    log_table : (3, 3) float
        ``log p[C_W][C_M]`` (:func:`~services.floor_plan.likelihood.log_sensor_table`).
    wall_cells : int
        The seed's band thickness (every wall's default shape is ``WallShape(0, wall_cells)``).
    fixed : (H, W) bool
        Cells the world draws as walls whatever the units are (the solid blocks).
    max_shift, max_thickness : int
        A wall's inner face moves at most ``max_shift`` cells either way; it is 1 to ``max_thickness`` cells thick.
    log_cost : float
        The prior's cost (nats, >= 0) of a wall drawn other than the default band.
    passes : int
        At most this many rounds over all walls (coordinate ascent stops earlier when no wall changes).

    >>> from services.floor_plan.likelihood import log_sensor_table
    >>> cm = np.full((12, 14), CellClass.UNKNOWN, np.uint8); cm[1:11, 1:13] = CellClass.WALL
    >>> cm[4:8, 4:10] = CellClass.FREE  # walls three cells thick round a room
    >>> w = World({1: Rect(2, 9, 2, 11)})  # the unit drawn with one-cell walls, one cell in from the map's
    >>> out = fit_walls(w, cm, log_sensor_table(), wall_cells=1, fixed=np.zeros(cm.shape, bool), max_shift=2,
    ...                 max_thickness=4, log_cost=1.0)
    >>> out.shapes[1][0], out.fitted, bool((out.classes_world == cm).all())
    (WallShape(shift=1, thickness=3), 4, True)
    """
    if classes_map.shape != fixed.shape:
        raise ValueError(f"C_M {classes_map.shape} and the fixed walls {fixed.shape} differ in shape")
    if max_shift < 0 or max_thickness < 1 or log_cost < 0 or wall_cells < 1:
        raise ValueError(f"need max_shift >= 0, max_thickness >= 1, log_cost >= 0, wall_cells >= 1, got "
                         f"{max_shift}, {max_thickness}, {log_cost}, {wall_cells}")
    t = wall_cells
    h, w = classes_map.shape
    ll = np.ascontiguousarray(log_table[:, classes_map])  # (3, H, W): log p(C_M | C_W = class)
    counts: _Counts = (np.zeros((h, w), np.int16), np.zeros((h, w), np.int16), np.zeros((h, w), np.int16))
    default = WallShape(0, t)
    shapes = {uid: (default,) * 4 for uid in world.units}
    doors: dict[int, dict[Side, list[Rect]]] = {uid: {} for uid in world.units}
    for d in world.doors:
        for uid in world.door_units(d, t):
            rect = world.units[uid]
            side = next(s for s in Side if wall_band(rect, s, t).contains(d))
            doors[uid].setdefault(side, []).append(d)
    for uid, rect in world.units.items():
        _add(counts, _faces(rect, shapes[uid], t), doors[uid], +1)
    for _ in range(passes):
        changed = False
        for uid in sorted(world.units):
            rect = world.units[uid]
            for side in Side:
                f = _faces(rect, shapes[uid], t)
                _add(counts, f, doors[uid], -1)
                best = _best(counts, ll, fixed, rect, f, side, doors[uid], shapes[uid], t=t, max_shift=max_shift,
                             max_thickness=max_thickness, log_cost=log_cost)
                if best != shapes[uid][side]:
                    changed = True
                    new = list(shapes[uid])
                    new[side] = best
                    shapes[uid] = (new[0], new[1], new[2], new[3])
                _add(counts, _faces(rect, shapes[uid], t), doors[uid], +1)
        if not changed:
            break
    out = _classes(*counts, fixed)
    fitted = sum(s != default for v in shapes.values() for s in v)
    return Walls(out, shapes, fitted)


def _best(
    counts: _Counts, ll: npt.NDArray[np.float64], fixed: npt.NDArray[np.bool_], rect: Rect, f: _Faces, side: Side,
    doors: dict[Side, list[Rect]], shapes: tuple[WallShape, ...], *, t: int, max_shift: int, max_thickness: int,
    log_cost: float,
) -> WallShape:
    """The best shape of one wall given everything else (the unit's contribution is off ``counts``)."""
    h, w = fixed.shape
    vertical = side in (Side.LEFT, Side.RIGHT)  # the wall runs along rows
    # the nominal inner face (first free row/column counted from this side) and the free space's far end
    face = {Side.TOP: rect.r0 + t, Side.BOTTOM: rect.r1 - t, Side.LEFT: rect.c0 + t, Side.RIGHT: rect.c1 - t}[side]
    far = {Side.TOP: f.a1 - face, Side.BOTTOM: face - f.a0, Side.LEFT: f.b1 - face, Side.RIGHT: face - f.b0}[side]
    room = face if side in (Side.TOP, Side.LEFT) else (w if vertical else h) - 1 - face  # cells outside the face
    hi = min(max_shift, far)  # the free space keeps at least one row
    k0, k1 = max(-max_shift - max_thickness, -room), hi - 1
    if hi < -max_shift or k1 < k0:
        return shapes[side]
    # along the wall: the perpendicular walls' outer faces bound it, their inner faces bound the free space
    if vertical:
        j0, j1, m0, m1 = f.a0 - f.w[Side.TOP], f.a1 + f.w[Side.BOTTOM], f.a0, f.a1
    else:
        j0, j1, m0, m1 = f.b0 - f.w[Side.LEFT], f.b1 + f.w[Side.RIGHT], f.b0, f.b1
    n_int, n_wall, n_door = (_oriented(c, side, face, k0, k1, j0, j1) for c in counts)
    fix = _oriented(fixed, side, face, k0, k1, j0, j1)
    lls = _oriented(ll, side, face, k0, k1, j0, j1)
    along = np.arange(j0, j1 + 1)
    mid = (along >= m0) & (along <= m1)
    across = np.arange(k0, k1 + 1)
    pos = face + across if side in (Side.TOP, Side.LEFT) else face - across  # absolute row/column of each k
    # the perpendicular walls' doors in the corner cells, and this wall's doors along it
    corner_door = np.zeros(n_int.shape, bool)
    for s in ((Side.LEFT, Side.RIGHT) if not vertical else (Side.TOP, Side.BOTTOM)):
        for d in doors.get(s, ()):
            lo, up = (d.r0, d.r1) if not vertical else (d.c0, d.c1)
            corner_door |= ((pos >= lo) & (pos <= up))[:, None] & ~mid[None, :]
    side_door = np.zeros(along.shape, bool)
    for d in doors.get(side, ()):
        lo, up = (d.c0, d.c1) if not vertical else (d.r0, d.r1)
        side_door |= (along >= lo) & (along <= up)

    def rows(n_i: npt.NDArray[np.integer], n_w: npt.NDArray[np.integer],
             n_d: npt.NDArray[np.integer]) -> npt.NDArray[np.float64]:
        cls = _classes(n_i, n_w, n_d, fix)
        out: npt.NDArray[np.float64] = np.take_along_axis(lls, cls[None], axis=0)[0].sum(axis=1)
        return out

    corner = ~mid[None, :]
    none = rows(n_int, n_wall, n_door)
    inside = rows(n_int + mid[None, :], n_wall + corner, n_door + corner_door)
    band = rows(n_int, n_wall + 1, n_door + (corner_door | side_door[None, :]))
    cn, cb, ci = (np.r_[0.0, np.cumsum(x)] for x in (none, band, inside))
    shift, thick = np.meshgrid(np.arange(-max_shift, hi + 1), np.arange(1, max_thickness + 1), indexing="ij")
    ok = shift - thick >= k0  # the band's first row (k) in the grid; its last is shift - 1
    shift, thick = shift[ok], thick[ok]
    a, b = shift - thick - k0, shift - k0  # rows before the band, rows up to the band's end
    score = cn[a] + (cb[b] - cb[a]) + (ci[-1] - ci[b]) - log_cost * ((shift != 0) | (thick != t))
    nominal = np.flatnonzero((shift == 0) & (thick == t))
    pick = int(np.argmax(score))
    if len(nominal) and score[nominal[0]] >= score[pick] - 1e-9:
        return WallShape(0, t)
    return WallShape(int(shift[pick]), int(thick[pick]))
