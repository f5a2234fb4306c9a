"""Walls as the map draws them: each unit wall's own thickness and offset, fitted after the chain.

The seed's world (section 3.4) draws every wall as a band of one thickness along the border of its unit's
rectangle. A real map's walls vary: freiburg's are 0.2 m on average but thinner and thicker in places, a wall
drawn by a laser from one side lies off the band by a cell or two, g4s_y2 draws them blurred. Given the units
and doors, each of a unit's four walls is drawn as a run of **segments** along it, each with its own **inner
face** (moved into the unit by ``shift`` cells, negative: outwards; the unit's free space reaches the inner
face) and **thickness** (cells from the inner face outwards; 0: no wall there, an opening), where a segment
other than the seed's band beats a prior cost per such segment. Segments start and end on a grid of
``segment_cells`` along the wall. A door stays an opening through its two walls at whatever shape they take.

A wall's best segments depend on its unit's other walls and on its neighbours' walls, so the walls are fitted by
coordinate ascent: each wall the exact best run of segments given all the others (dynamic programming along the
wall), until none changes: a maximum of the posterior over wall shapes for the given units, not necessarily
the global one. The chain does not see them.
"""

from __future__ import annotations

import functools
from typing import NamedTuple, TypeVar

import numpy as np
import numpy.typing as npt

from services.floor_plan.likelihood import CellClass
from services.floor_plan.world import Rect, Side, World, wall_band

_T = TypeVar("_T", bound=np.generic)


class Segment(NamedTuple):
    """A piece of a unit's wall: cells ``start..end`` along it (rows for the left and right walls, columns for the
    top and bottom ones), its inner face moved ``shift`` cells into the unit (negative: outwards) and its
    ``thickness`` in cells outwards from that face (0: an opening). The seed's band is ``shift`` 0, ``thickness``
    the world's wall cells."""

    start: int
    end: int
    shift: int
    thickness: int


class Slant(NamedTuple):
    """A wall at an angle to the grid that cuts a unit's rectangle along a line (cell-centre coordinates of the
    working frame): the unit keeps the cells with ``d < -thickness``, ``d = (row - row0) * normal_row + (col - col0)
    * normal_col``, draws the cells with ``-thickness <= d < 0`` as its wall and gives up the rest (outside)."""

    row0: float
    col0: float
    normal_row: float
    normal_col: float
    thickness: float


class Walls(NamedTuple):
    """The world's rendering with fitted walls and the walls' shapes."""

    classes_world: npt.NDArray[np.uint8]
    """C_W (working frame) with every wall drawn as fitted and the fixed walls drawn as walls."""
    segments: dict[int, tuple[tuple[Segment, ...], ...]]
    """Per unit id, its four walls (:class:`~services.floor_plan.world.Side` order) as segments, from the low
    end; a wall drawn as the seed's band is one segment."""
    fitted: int
    """How many segments differ from the seed's band."""
    slants: dict[int, tuple[Slant, ...]]
    """Per unit id, the slanted walls that cut it (none for most units)."""


_Counts = tuple[npt.NDArray[np.int16], npt.NDArray[np.int16], npt.NDArray[np.int16]]


def _classes(n_int: npt.NDArray[np.integer], n_wall: npt.NDArray[np.integer], n_door: npt.NDArray[np.integer],
             fixed: npt.NDArray[np.bool_]) -> npt.NDArray[np.uint8]:
    wall = ((n_wall > 0) & (n_door == 0)) | fixed
    free = ~wall & ((n_int > 0) | (n_door > 0))
    out = np.where(wall, np.uint8(CellClass.WALL), np.where(free, np.uint8(CellClass.FREE),
                                                                np.uint8(CellClass.UNKNOWN)))
    return out.astype(np.uint8)


def _oriented(grid: npt.NDArray[_T], side: Side, face: int, k0: int, k1: int, j0: int, j1: int) -> npt.NDArray[_T]:
    """A view of ``grid`` at offsets ``k0..k1`` from ``face`` into the unit (rows of the view) and ``j0..j1``
    along the wall (columns of the view)."""
    match side:
        case Side.TOP:
            return grid[..., face + k0 : face + k1 + 1, j0 : j1 + 1]
        case Side.BOTTOM:
            return grid[..., face - k1 : face - k0 + 1, j0 : j1 + 1][..., ::-1, :]
        case Side.LEFT:
            return np.swapaxes(grid[..., j0 : j1 + 1, face + k0 : face + k1 + 1], -1, -2)
        case _:
            return np.swapaxes(grid[..., j0 : j1 + 1, face - k1 : face - k0 + 1][..., ::-1], -1, -2)


class _Strip(NamedTuple):
    """The cells one wall of a unit can change: ``k0..k1`` from its nominal inner face ``face`` into the unit,
    ``j0..j1`` along it; ``mid`` marks the positions along it that face the unit's free space, ``door`` the
    positions a door opens."""

    side: Side
    face: int
    k0: int
    k1: int
    j0: int
    j1: int
    mid: npt.NDArray[np.bool_]
    door: npt.NDArray[np.bool_]

    def view(self, grid: npt.NDArray[_T]) -> npt.NDArray[_T]:
        return _oriented(grid, self.side, self.face, self.k0, self.k1, self.j0, self.j1)


def _box(strip: _Strip) -> tuple[int, int, int, int]:
    """The cells a wall's strip covers (:meth:`_Strip.view`), as inclusive row and column bounds."""
    lo, hi = strip.face + strip.k0, strip.face + strip.k1
    if strip.side in (Side.BOTTOM, Side.RIGHT):
        lo, hi = strip.face - strip.k1, strip.face - strip.k0
    if strip.side in (Side.TOP, Side.BOTTOM):
        return lo, hi, strip.j0, strip.j1
    return strip.j0, strip.j1, lo, hi


def _strips(rect: Rect, doors: list[Rect], shape: tuple[int, int], *, t: int, depth: int,
            reach: int) -> tuple[list[_Strip], Rect]:
    """A unit's four wall strips (``depth`` cells into the unit, ``reach`` outside its nominal inner face) and the
    core of its free space no wall may change."""
    h, w = shape
    a0, a1, b0, b1 = rect.r0 + t, rect.r1 - t, rect.c0 + t, rect.c1 - t
    strips = []
    for side in Side:
        vertical = side in (Side.LEFT, Side.RIGHT)
        face = (a0, a1, b0, b1)[side]
        room = face if side in (Side.TOP, Side.LEFT) else (w if vertical else h) - 1 - face
        j0, j1, m0, m1 = (rect.r0, rect.r1, a0, a1) if vertical else (rect.c0, rect.c1, b0, b1)
        along = np.arange(j0, j1 + 1)
        door = np.zeros(along.shape, bool)
        for d in doors:
            if wall_band(rect, side, t).contains(d):
                lo, up = (d.r0, d.r1) if vertical else (d.c0, d.c1)
                door |= (along >= lo) & (along <= up)
        strips.append(_Strip(side, face, -min(reach, room), depth - 1, j0, j1, (along >= m0) & (along <= m1), door))
    return strips, Rect(a0 + depth, a1 - depth, b0 + depth, b1 - depth)


def _masks(strip: _Strip, shift: npt.NDArray[np.integer],
           thick: npt.NDArray[np.integer]) -> tuple[npt.NDArray[np.bool_], npt.NDArray[np.bool_]]:
    """(free space, wall) a wall drawn with ``shift``/``thick`` per position along it puts in its strip."""
    k = np.arange(strip.k0, strip.k1 + 1)[:, None]
    wall = (k >= shift - thick) & (k < shift)
    return (k >= shift) & strip.mid, wall


def _draw(counts: _Counts, strip: _Strip, shift: npt.NDArray[np.integer], thick: npt.NDArray[np.integer],
          sign: int) -> None:
    free, wall = _masks(strip, shift, thick)
    n_int, n_wall, n_door = (strip.view(c) for c in counts)
    n_int += sign * free
    n_wall += sign * wall
    n_door += sign * (wall & strip.door)


def fit_walls(
    world: World, classes_map: npt.NDArray[np.uint8], log_table: npt.NDArray[np.float64], *, wall_cells: int,
    fixed: npt.NDArray[np.bool_], max_shift: int, max_thickness: int, log_cost: float, segment_cells: int,
    passes: int = 4, lines: npt.NDArray[np.float64] | None = None, max_slants: int = 2,
) -> Walls:
    """Fit every unit wall's segments (inner face, thickness) to the map, given the units and doors.

    Parameters
    ----------
    world : World
        Units and doors in cells of ``classes_map``'s grid.
    classes_map : (H, W) uint8
        C_M (:class:`~services.floor_plan.likelihood.CellClass`) in the world's grid.
    log_table : (3, 3) float
        ``log p[C_W][C_M]`` (:func:`~services.floor_plan.likelihood.log_sensor_table`).
    wall_cells : int
        The seed's band thickness (every wall's default segment is ``shift`` 0, ``thickness`` ``wall_cells``).
    fixed : (H, W) bool
        Cells the world draws as walls whatever the units are (the solid blocks).
    max_shift, max_thickness : int
        A segment's inner face moves at most ``max_shift`` cells either way (into the unit at most to a third of
        its free space); it is 0 (an opening) to ``max_thickness`` cells thick.
    log_cost : float
        The prior's cost (nats, >= 0) of a segment other than the seed's band.
    segment_cells : int
        Segments start and end on a grid of this many cells along each wall.
    passes : int
        At most this many rounds over all walls (coordinate ascent stops earlier when no wall changes).
    lines : (N, 4) float, optional
        Wall lines at an angle to the grid (:func:`~services.floor_plan.detectors.wall_line_segments`,
        ``x0, y0, x1, y1`` cell centres). After the walls, a unit a line runs through may be cut along it
        (:class:`Slant`): the part beyond the line given up, a wall drawn along it, where that beats ``log_cost``;
        the unit's centre and doors stay. At most ``max_slants`` per unit, best first.

    >>> from services.floor_plan.likelihood import log_sensor_table
    >>> cm = np.full((12, 14), CellClass.UNKNOWN, np.uint8); cm[2:10, 2:12] = CellClass.WALL
    >>> cm[5:7, 5:9] = CellClass.FREE  # walls three cells thick round a room
    >>> w = World({1: Rect(2, 9, 2, 11)})  # the unit drawn with one-cell walls
    >>> out = fit_walls(w, cm, log_sensor_table(), wall_cells=1, fixed=np.zeros(cm.shape, bool), max_shift=2,
    ...                 max_thickness=4, log_cost=1.0, segment_cells=2)
    >>> out.segments[1][0][0], out.fitted, bool((out.classes_world == cm).all())
    (Segment(start=2, end=11, shift=2, thickness=3), 4, True)
    """
    if classes_map.shape != fixed.shape:
        raise ValueError(f"C_M {classes_map.shape} and the fixed walls {fixed.shape} differ in shape")
    if min(max_shift, log_cost) < 0 or min(max_thickness, wall_cells, segment_cells) < 1:
        raise ValueError(f"need max_shift >= 0, log_cost >= 0, max_thickness, wall_cells, segment_cells >= 1, got "
                         f"{max_shift}, {log_cost}, {max_thickness}, {wall_cells}, {segment_cells}")
    t = wall_cells
    max_thickness = max(max_thickness, t)
    shape = (int(classes_map.shape[0]), int(classes_map.shape[1]))
    ll = np.ascontiguousarray(log_table[:, classes_map])  # (3, H, W): log p(C_M | C_W = class)
    counts: _Counts = (np.zeros(shape, np.int16), np.zeros(shape, np.int16), np.zeros(shape, np.int16))
    doors: dict[int, list[Rect]] = {uid: [] for uid in world.units}
    for d in world.doors:
        for uid in world.door_units(d, t):
            doors[uid].append(d)
    strips: dict[int, list[_Strip]] = {}
    drawn: dict[tuple[int, Side], tuple[npt.NDArray[np.int64], npt.NDArray[np.int64]]] = {}
    def depth_of(rect: Rect) -> int:
        return max(0, min(max_shift, (min(rect.rows, rect.cols) - 2 * t) // 3))  # free space keeps a third

    for uid, rect in world.units.items():
        depth = depth_of(rect)
        strips[uid], core = _strips(rect, doors[uid], shape, t=t, depth=depth, reach=max_shift + max_thickness)
        if core.r0 <= core.r1 and core.c0 <= core.c1:
            counts[0][core.r0 : core.r1 + 1, core.c0 : core.c1 + 1] += 1
        for strip in strips[uid]:
            n = strip.j1 - strip.j0 + 1
            drawn[uid, strip.side] = (np.zeros(n, np.int64), np.full(n, t, np.int64))
            _draw(counts, strip, *drawn[uid, strip.side], +1)
    # a wall's best segments depend only on the counts in its strip: after the first pass, a wall is fitted again only
    # when a wall whose strip overlaps its own has changed since (any other wall would come back as it is drawn)
    keys = [(uid, strip.side) for uid in sorted(world.units) for strip in strips[uid]]
    by_key = {(uid, strip.side): strip for uid in world.units for strip in strips[uid]}
    boxes = np.array([_box(by_key[key]) for key in keys], np.int64).reshape(-1, 4)
    overlaps = ((boxes[:, None, 0] <= boxes[None, :, 1]) & (boxes[None, :, 0] <= boxes[:, None, 1])
                & (boxes[:, None, 2] <= boxes[None, :, 3]) & (boxes[None, :, 2] <= boxes[:, None, 3]))
    np.fill_diagonal(overlaps, False)
    dirty = np.ones(len(keys), bool)
    for _ in range(passes):
        changed = False
        for i, key in enumerate(keys):
            if not dirty[i]:
                continue
            dirty[i] = False
            strip = by_key[key]
            old = drawn[key]
            _draw(counts, strip, *old, -1)
            new = _best(counts, ll, fixed, strip, t=t, max_shift=max_shift, max_thickness=max_thickness,
                        log_cost=log_cost, segment_cells=segment_cells)
            if not (np.array_equal(new[0], old[0]) and np.array_equal(new[1], old[1])):
                changed = True
                drawn[key] = new
                dirty |= overlaps[i]
            _draw(counts, strip, *drawn[key], +1)
        if not changed:
            break
    segments = {uid: tuple(_segments(strip, *drawn[uid, strip.side]) for strip in strips[uid])
                for uid in world.units}
    fitted = sum(s.shift != 0 or s.thickness != t for walls in segments.values() for wall in walls for s in wall)
    slants: dict[int, tuple[Slant, ...]] = {uid: () for uid in world.units}
    if lines is not None and len(lines) and max_slants > 0:
        reach = max_shift + max_thickness
        scratch: _Counts = (np.zeros(shape, np.int16), np.zeros(shape, np.int16), np.zeros(shape, np.int16))
        for uid, rect in sorted(world.units.items()):
            own = _Own.of(rect, reach, shape, scratch, strips[uid], drawn, uid, doors[uid], t=t, depth=depth_of(rect))
            for _ in range(max_slants):
                cut = _best_slant(counts, ll, fixed, own, rect, lines, t=t, log_cost=log_cost,
                                  min_inside=segment_cells)
                if cut is None:
                    break
                own.cut(counts, cut)
                slants[uid] += (cut,)
    return Walls(_classes(*counts, fixed), segments, fitted, slants)


def _segments(strip: _Strip, shift: npt.NDArray[np.int64], thick: npt.NDArray[np.int64]) -> tuple[Segment, ...]:
    cut = np.flatnonzero((np.diff(shift) != 0) | (np.diff(thick) != 0)) + 1
    starts = np.r_[0, cut]
    ends = np.r_[cut - 1, len(shift) - 1]
    return tuple(Segment(strip.j0 + int(a), strip.j0 + int(b), int(shift[a]), int(thick[a]))
                 for a, b in zip(starts, ends, strict=True))


@functools.lru_cache(maxsize=256)
def _options(k0: int, k1: int, *, t: int, max_shift: int, max_thickness: int, log_cost: float) -> tuple[
        npt.NDArray[np.int64], npt.NDArray[np.int64], npt.NDArray[np.int64], npt.NDArray[np.int64], int,
        npt.NDArray[np.float64]]:
    """A wall strip's options (``k0..k1`` as in :class:`_Strip`): each (shift, thickness), the rows before its band
    and up to its band's end, the seed's band among them and each option's cost of entering it (read-only)."""
    grid = np.meshgrid(np.arange(-max_shift, k1 + 2), np.arange(max_thickness + 1), indexing="ij")
    ok = grid[0] - grid[1] >= k0  # the band's first row is in the strip
    shift, thick = grid[0][ok], grid[1][ok]
    a, b = shift - thick - k0, shift - k0  # rows before the band, rows up to the band's end
    default = int(np.flatnonzero((shift == 0) & (thick == t))[0])
    enter = np.full(len(shift), log_cost)  # a segment other than the seed's band costs log_cost
    enter[default] = 0.0
    for array in (shift, thick, a, b, enter):
        array.flags.writeable = False
    return shift, thick, a, b, default, enter


def _best(
    counts: _Counts, ll: npt.NDArray[np.float64], fixed: npt.NDArray[np.bool_], strip: _Strip, *, t: int,
    max_shift: int, max_thickness: int, log_cost: float, segment_cells: int,
) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int64]]:
    """The best segments of one wall given everything else (its own cells are off ``counts``): per position along
    the wall its (shift, thickness)."""
    n_int, n_wall, n_door = (strip.view(c) for c in counts)
    fix = strip.view(fixed)
    ll_free, ll_unknown, ll_wall = (strip.view(ll[k]) for k in (CellClass.FREE, CellClass.UNKNOWN, CellClass.WALL))
    some_int, some_wall, some_door = n_int > 0, n_wall > 0, n_door > 0

    def cumulative(has_int: npt.NDArray[np.bool_], has_wall: npt.NDArray[np.bool_],
                   has_door: npt.NDArray[np.bool_]) -> npt.NDArray[np.float64]:
        wall = (has_wall & ~has_door) | fix  # as _classes draws it
        cells = np.where(wall, ll_wall, np.where(has_int | has_door, ll_free, ll_unknown))
        return np.concatenate([np.zeros((1, cells.shape[1])), np.cumsum(cells, axis=0)])

    none = cumulative(some_int, some_wall, some_door)
    band = cumulative(some_int, n_wall >= 0, some_door | strip.door)  # n_wall + 1 > 0
    inside = cumulative(some_int | strip.mid, some_wall, some_door)
    shift, thick, a, b, default, enter = _options(strip.k0, strip.k1, t=t, max_shift=max_shift,
                                                  max_thickness=max_thickness, log_cost=log_cost)
    per_cell = none[a] + band[b] - band[a] + inside[-1] - inside[b]  # (options, positions along)
    per_cell -= 1e-6 * thick[:, None]  # where the map cannot tell (a free cell drawn wall or unknown), less wall
    blocks = np.arange(0, per_cell.shape[1], segment_cells)
    score = np.add.reduceat(per_cell, blocks, axis=1)
    value = score[:, 0] - enter
    back = np.zeros(score.shape, np.int64)
    for i in range(1, score.shape[1]):
        top = int(np.argmax(value))
        switch = value[top] - enter
        stay = value >= switch - 1e-9
        back[:, i] = np.where(stay, np.arange(len(value)), top)
        value = score[:, i] + np.where(stay, value, switch)
    best = default if value[default] >= value.max() - 1e-9 else int(np.argmax(value))
    choice = np.empty(score.shape[1], np.int64)
    for i in range(score.shape[1] - 1, -1, -1):
        choice[i] = best
        best = int(back[best, i])
    per_position = np.repeat(choice, np.diff(np.r_[blocks, per_cell.shape[1]]))
    return shift[per_position], thick[per_position]


class _Own:
    """One unit's own counts (free space, wall, door) in a window round its rectangle, so that a slanted wall can
    take them off the world's counts where it cuts the unit."""

    def __init__(self, window: tuple[slice, slice], counts: _Counts, keep: npt.NDArray[np.float64]) -> None:
        self.window = window
        self.counts = counts
        self.keep = keep
        """(N, 2) cells (row, column) every cut keeps: the unit's centre and its doors' corners."""

    @classmethod
    def of(cls, rect: Rect, reach: int, shape: tuple[int, int], scratch: _Counts, strips: list[_Strip],
           drawn: dict[tuple[int, Side], tuple[npt.NDArray[np.int64], npt.NDArray[np.int64]]], uid: int,
           doors: list[Rect], *, t: int, depth: int) -> _Own:
        window = (slice(max(rect.r0 - reach, 0), min(rect.r1 + reach + 1, shape[0])),
                  slice(max(rect.c0 - reach, 0), min(rect.c1 + reach + 1, shape[1])))
        a0, a1, b0, b1 = rect.r0 + t + depth, rect.r1 - t - depth, rect.c0 + t + depth, rect.c1 - t - depth
        if a0 <= a1 and b0 <= b1:
            scratch[0][a0 : a1 + 1, b0 : b1 + 1] += 1
        for strip in strips:
            _draw(scratch, strip, *drawn[uid, strip.side], +1)
        own = (scratch[0][window].copy(), scratch[1][window].copy(), scratch[2][window].copy())
        for c in scratch:
            c[window] = 0
        keep = [((rect.r0 + rect.r1) / 2, (rect.c0 + rect.c1) / 2)]
        keep += [(r, c) for d in doors for r in (d.r0, d.r1) for c in (d.c0, d.c1)]
        return cls(window, own, np.array(keep, np.float64))

    def cut(self, counts: _Counts, slant: Slant) -> None:
        d = _distance(self.window, slant)
        n_int, n_wall, n_door = self.counts
        foot = (n_int > 0) | (n_wall > 0) | (n_door > 0)
        drop = foot & (d >= 0)
        band = foot & (d >= -slant.thickness) & (d < 0)
        new = (np.where(drop | band, 0, n_int).astype(np.int16),
               np.where(band, 1, np.where(drop, 0, n_wall)).astype(np.int16),
               np.where(drop, 0, n_door).astype(np.int16))
        for total, old, now in zip(counts, self.counts, new, strict=True):
            total[self.window] += now - old
        self.counts = new


def _distance(window: tuple[slice, slice], slant: Slant) -> npt.NDArray[np.float64]:
    rows = np.arange(window[0].start, window[0].stop, dtype=np.float64)[:, None]
    cols = np.arange(window[1].start, window[1].stop, dtype=np.float64)[None, :]
    out: npt.NDArray[np.float64] = (rows - slant.row0) * slant.normal_row + (cols - slant.col0) * slant.normal_col
    return out


def _inside(lines: npt.NDArray[np.float64], r0: float, r1: float, c0: float, c1: float) -> npt.NDArray[np.float64]:
    """How long each segment (``x0, y0, x1, y1``) runs inside rows ``r0..r1``, columns ``c0..c1`` (Liang-Barsky)."""
    x0, y0, dx, dy = lines[:, 0], lines[:, 1], lines[:, 2] - lines[:, 0], lines[:, 3] - lines[:, 1]
    lo, up = np.zeros(len(lines)), np.ones(len(lines))
    for p, a, b in ((dx, c0 - x0, c1 - x0), (dy, r0 - y0, r1 - y0)):
        with np.errstate(divide="ignore", invalid="ignore"):
            ta, tb = a / p, b / p
        flat = p == 0
        lo = np.maximum(lo, np.where(flat, np.where(a <= 0, 0.0, 2.0), np.minimum(ta, tb)))
        up = np.minimum(up, np.where(flat, np.where(b >= 0, 1.0, -1.0), np.maximum(ta, tb)))
    out: npt.NDArray[np.float64] = np.clip(up - lo, 0.0, None) * np.hypot(dx, dy)
    return out


def _best_slant(
    counts: _Counts, ll: npt.NDArray[np.float64], fixed: npt.NDArray[np.bool_], own: _Own, rect: Rect,
    lines: npt.NDArray[np.float64], *, t: int, log_cost: float, min_inside: int, reach_half: int = 4,
) -> Slant | None:
    """The slanted wall that explains the map best where it cuts the unit (its line through one of ``lines``, moved
    up to ``reach_half`` half cells either way, ``t`` to ``t + 1`` cells thick) that keeps the unit's centre and doors,
    if it beats ``log_cost``."""
    a0, a1, b0, b1 = rect.r0 + t, rect.r1 - t, rect.c0 + t, rect.c1 - t
    lines = lines[_inside(lines, a0, a1, b0, b1) >= min_inside]
    if not len(lines):
        return None
    n_int, n_wall, n_door = (c[own.window] for c in counts)
    o_int, o_wall, o_door = own.counts
    fix, lls = fixed[own.window], ll[(slice(None), *own.window)]

    def cell_ll(cls: npt.NDArray[np.uint8]) -> npt.NDArray[np.float64]:
        out: npt.NDArray[np.float64] = np.take_along_axis(lls, cls[None], axis=0)[0]
        return out

    old = cell_ll(_classes(n_int, n_wall, n_door, fix))
    foot = (o_int > 0) | (o_wall > 0) | (o_door > 0)
    g_drop = cell_ll(_classes(n_int - o_int, n_wall - o_wall, n_door - o_door, fix))[foot] - old[foot]
    g_band = cell_ll(_classes(n_int - o_int, n_wall - o_wall + 1, n_door - o_door, fix))[foot] - old[foot]
    if np.maximum(np.maximum(g_drop, g_band), 0.0).sum() <= log_cost:
        return None  # no cut can pay
    rows, cols = np.nonzero(foot)
    rows, cols = rows + own.window[0].start, cols + own.window[1].start
    widths = np.arange(2 * t, 2 * t + 3)  # half cells
    lo = -reach_half - int(widths[-1]) - 1
    size = reach_half - lo + 1
    q = np.arange(-reach_half, reach_half + 1)
    qi, wi = q[:, None] - lo, widths[None, :]
    length = np.hypot(lines[:, 2] - lines[:, 0], lines[:, 3] - lines[:, 1])
    normals = np.stack([(lines[:, 2] - lines[:, 0]) / length, -(lines[:, 3] - lines[:, 1]) / length], axis=1)
    # branch and bound: a cut gains at most its far side's cells where every position puts them beyond the line
    # and, nearer, each cell's best; summed over blocks of 8 x 8 cells (a block's cells lie within `slack` half
    # cells of its centre's distance), the most promising cut first
    per_row = 1 + own.window[1].stop // 8
    keys, where = np.unique((rows // 8) * per_row + cols // 8, return_inverse=True)
    beyond = np.bincount(where, g_drop)
    gaining = np.bincount(where, np.maximum(np.maximum(g_drop, g_band), 0.0))
    far = 2 * (((keys // per_row) * 8 + 3.5)[:, None] - lines[None, :, 1]) * normals[None, :, 0] \
        + 2 * (((keys % per_row) * 8 + 3.5)[:, None] - lines[None, :, 0]) * normals[None, :, 1]  # (blocks, lines)
    slack = 7 * np.sqrt(2)
    bound = np.stack([beyond @ (f - slack >= reach_half) + gaining @ ((f + slack > lo) & (f - slack < reach_half))
                      for f in (far, -far)], axis=1)  # (lines, sign)
    best: tuple[float, Slant] | None = None
    for flat in np.argsort(-bound, axis=None):
        k, side = divmod(int(flat), 2)
        if bound[k, side] <= max(log_cost, -np.inf if best is None else best[0]):
            break
        x0, y0 = lines[k, 0], lines[k, 1]
        nr, nc = normals[k]
        d = 2 * ((rows - y0) * nr + (cols - x0) * nc)
        keep = 2 * ((own.keep[:, 0] - y0) * nr + (own.keep[:, 1] - x0) * nc)
        for sign in ((1.0,) if side == 0 else (-1.0,)):
            half = np.clip(np.floor(sign * d), lo, reach_half).astype(np.int64) - lo
            drop = np.cumsum(np.bincount(half, g_drop, size)[::-1])[::-1]  # sum over b >= index
            band = np.r_[0.0, np.cumsum(np.bincount(half, g_band, size))]  # sum over b < index
            kept = np.floor(np.max(sign * keep)) < q[:, None] - wi  # the centre and the doors stay
            gain = np.where(kept, drop[qi] + band[qi] - band[qi - wi], -np.inf)
            i, j = np.unravel_index(int(np.argmax(gain)), gain.shape)
            if gain[i, j] > log_cost and (best is None or gain[i, j] > best[0]):
                shift = q[i] / 2
                best = (float(gain[i, j]), Slant(y0 + shift * sign * nr, x0 + shift * sign * nc, sign * nr, sign * nc,
                                                 float(widths[j]) / 2))
    return None if best is None else best[1]
