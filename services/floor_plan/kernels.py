"""The five reversible kernel pairs (section 3.5.1) with exact proposal probabilities.

Every kernel is a pair of functions: ``draw`` proposes a :class:`Move` by a sequence of weighted picks
(eqs. 3.15-3.17, through a :class:`Chooser`), and ``probability`` gives the *total* probability that the
kernel proposes that move from a world (summing every way of drawing it). The Metropolis-Hastings ratio
Q(W|W')/Q(W'|W) (eq. 3.9) is ``probability`` of the reverse kernel on W' over ``probability`` on W, so the
chain keeps detailed balance; the tests check it by enumerating every draw on a tiny world.
"""

from __future__ import annotations

import bisect
import enum
import itertools
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import NamedTuple, Protocol

import numpy as np
import numpy.typing as npt

from services.floor_plan.detectors import (
    Candidate,
    Evidence,
    WallLines,
    door_candidates,
    split_options,
    split_rect,
)
from services.floor_plan.world import Rect, Side, World, moved


class Kernel(enum.Enum):
    """The MC sub-kernels of table 3.2."""

    ADD = "add"
    REMOVE = "remove"
    SPLIT = "split"
    MERGE = "merge"
    SHRINK = "shrink"
    DILATE = "dilate"
    INTERCHANGE = "interchange"
    ALLOCATE = "allocate"
    DELETE = "delete"


REVERSE: dict[Kernel, Kernel] = {
    Kernel.ADD: Kernel.REMOVE, Kernel.REMOVE: Kernel.ADD, Kernel.SPLIT: Kernel.MERGE, Kernel.MERGE: Kernel.SPLIT,
    Kernel.SHRINK: Kernel.DILATE, Kernel.DILATE: Kernel.SHRINK, Kernel.INTERCHANGE: Kernel.INTERCHANGE,
    Kernel.ALLOCATE: Kernel.DELETE, Kernel.DELETE: Kernel.ALLOCATE,
}


class Chooser(Protocol):
    """Draws an index with probability proportional to non-negative ``weights`` (not all zero)."""

    def pick(self, weights: npt.NDArray[np.float64]) -> int: ...


class RandomChooser:
    """Eqs. 3.15-3.17: normalise, accumulate, take the first index whose cumulative weight reaches k ~ U[0,1)."""

    def __init__(self, rng: np.random.Generator) -> None:
        self.rng = rng

    def pick(self, weights: npt.NDArray[np.float64]) -> int:
        if len(weights) > 64:
            cum = np.cumsum(weights)
            return min(int(np.searchsorted(cum, self.rng.random() * cum[-1], side="right")), len(weights) - 1)
        # Short arrays (almost every pick): the same sequential sums and search in plain floats, which is
        # several times cheaper than two numpy calls on a handful of values.
        acc = list(itertools.accumulate(weights.tolist()))
        return min(bisect.bisect_right(acc, self.rng.random() * acc[-1]), len(acc) - 1)


class Move(NamedTuple):
    """A proposed change. ``removed`` unit ids give way to ``added`` rectangles; for SHRINK/DILATE, SPLIT,
    MERGE and INTERCHANGE the first added units take over the removed ids in order."""

    kernel: Kernel
    removed: tuple[int, ...] = ()
    added: tuple[Rect, ...] = ()
    door_added: Rect | None = None
    door_removed: Rect | None = None
    detail: tuple[int, ...] = ()  # SHRINK/DILATE: (side, cells); SPLIT/MERGE: (axis, position)
    window: tuple[Rect, ...] = ()  # cells the move can change (for the incremental likelihood)


@dataclass(frozen=True)
class KernelSettings:
    """Tuning of the proposals (cells are grid cells of the working frame)."""

    wall_cells: int = 2
    min_inner_cells: int = 4
    shift_sigma_cells: float = 3.0
    max_shift_cells: int = 8
    h_b: float = 10.0  # eq. 3.21
    h_v: float = 10.0  # eq. 3.22
    h_g: float = 10.0  # eq. 3.28
    min_door_cells: int = 10
    free_space_share: float = 0.5  # ADD: chance of drawing from the FSU candidates when there are any


def _dedup(candidates: list[Candidate]) -> list[Candidate]:
    best: dict[Rect, float] = {}
    for c in candidates:
        best[c.rect] = max(best.get(c.rect, 0.0), c.weight)
    return [Candidate(r, w) for r, w in best.items() if w > 0]


def _inverse_weight(w: float, cap: float) -> float:
    """Eqs. 3.21, 3.22, 3.28: 1/w capped at ``cap``."""
    return cap if w <= 1.0 / cap else 1.0 / w


@dataclass
class Proposer:
    """Kernels over one map: its evidence, wall lines and unit candidates."""

    evidence: Evidence
    lines: WallLines
    settings: KernelSettings
    candidates: list[Candidate] = field(default_factory=list)
    free_space: list[Candidate] = field(default_factory=list)
    _cand_prob: dict[Rect, float] = field(default_factory=dict)
    _sets: list[tuple[list[Rect], npt.NDArray[np.float64]]] = field(default_factory=list)
    _set_shares: npt.NDArray[np.float64] = field(default_factory=lambda: np.zeros(0))
    _b: dict[Rect, float] = field(default_factory=dict)
    _v: dict[Rect, npt.NDArray[np.float64]] = field(default_factory=dict)
    _splits: dict[Rect, tuple[npt.NDArray[np.int64], npt.NDArray[np.int64], npt.NDArray[np.float64]]] = field(
        default_factory=dict)
    _doors: dict[frozenset[Rect], tuple[list[Rect], npt.NDArray[np.float64]]] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.set_candidates(self.candidates, self.free_space)
        g = np.exp(-np.arange(1, self.settings.max_shift_cells + 1) ** 2 / (2 * self.settings.shift_sigma_cells**2))
        self._shift = g / g.sum()

    def set_candidates(self, candidates: list[Candidate], free_space: list[Candidate] | None = None) -> None:
        """Replace the ADD candidates: wall-based ones and (optionally) free-space ones.

        ADD draws from each set with probability ``free_space_share`` / its complement when both are
        non-empty (eqs. 3.15-3.17 within a set); duplicates within a set keep their best weight.
        """
        self.candidates = _dedup(candidates)
        self.free_space = _dedup(free_space or [])
        sets = [c for c in (self.candidates, self.free_space) if c]
        share = self.settings.free_space_share if len(sets) == 2 else 1.0
        self._sets = [([c.rect for c in cs], np.array([c.weight for c in cs], np.float64)) for cs in sets]
        self._set_shares = np.array([1.0 - share, share][: len(sets)] if len(sets) == 2 else [1.0] * len(sets))
        self._cand_prob = {}
        for (rects, w), set_share in zip(self._sets, self._set_shares, strict=True):
            for r, p in zip(rects, w / w.sum(), strict=True):
                self._cand_prob[r] = self._cand_prob.get(r, 0.0) + float(set_share * p)

    # --- weights --------------------------------------------------------------------------------------
    def unit_b(self, rect: Rect) -> float:
        b = self._b.get(rect)
        if b is None:
            b = _inverse_weight(self.evidence.unit_weight(rect, self.settings.wall_cells), self.settings.h_b)
            self._b[rect] = b
        return b

    def wall_v(self, rect: Rect) -> npt.NDArray[np.float64]:
        v = self._v.get(rect)
        if v is None:
            t = self.settings.wall_cells
            v = np.array([_inverse_weight(self.evidence.wall_weight(rect, s, t), self.settings.h_v) for s in Side])
            self._v[rect] = v
        return v

    def splits(self, rect: Rect) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int64], npt.NDArray[np.float64]]:
        s = self._splits.get(rect)
        if s is None:
            s = split_options(rect, self.lines, wall_cells=self.settings.wall_cells,
                              min_inner_cells=self.settings.min_inner_cells)
            self._splits[rect] = s
        return s

    def doors(self, world: World) -> tuple[list[Rect], npt.NDArray[np.float64]]:
        key = frozenset(world.units.values())
        d = self._doors.get(key)
        if d is None:
            cands = door_candidates(world, self.evidence, wall_cells=self.settings.wall_cells,
                                    min_door_cells=self.settings.min_door_cells)
            d = ([c.rect for c in cands], np.array([c.weight for c in cands], np.float64))
            if len(self._doors) > 256:
                self._doors.clear()
            self._doors[key] = d
        return d

    def valid(self, rect: Rect) -> bool:
        t, m = self.settings.wall_cells, self.settings.min_inner_cells
        h, w = self.evidence.shape
        return (rect.r0 >= 0 and rect.c0 >= 0 and rect.r1 < h and rect.c1 < w
                and rect.rows >= 2 * t + m and rect.cols >= 2 * t + m)

    def _b_all(self, world: World) -> tuple[list[int], npt.NDArray[np.float64]]:
        ids = list(world.units)
        b = [self._b.get(r) for r in world.units.values()]  # cached for almost every unit: skip the method call
        return ids, np.array([self.unit_b(r) if v is None else v for r, v in zip(world.units.values(), b, strict=True)],
                             np.float64)

    def _pair_weights(self, world: World, first: int) -> tuple[list[int], npt.NDArray[np.float64]]:
        """a_r(s) (eq. 3.20): the other units weighted by the reciprocal distance of the centres."""
        cr = world.units[first].centre()
        ids = [i for i in world.units if i != first]
        d = np.array([math.dist(cr, ((r.r0 + r.r1) / 2.0, (r.c0 + r.c1) / 2.0))  # Rect.centre, inlined
                      for r in (world.units[i] for i in ids)], np.float64)
        return ids, 1.0 / np.maximum(d, 1.0)

    def _pair_probability(self, world: World, u: int, v: int) -> float:
        n = len(world.units)
        total = 0.0
        for a, b in ((u, v), (v, u)):
            ids, w = self._pair_weights(world, a)
            total += w[ids.index(b)] / w.sum() / n
        return total

    # --- draw -----------------------------------------------------------------------------------------
    def draw(self, kernel: Kernel, world: World, chooser: Chooser) -> Move | None:
        """A move of ``kernel`` from ``world``, or None when the kernel has nothing to propose."""
        return _DRAW[kernel](self, world, chooser)

    def probability(self, world: World, move: Move) -> float:
        """The total probability that ``move.kernel`` proposes ``move`` from ``world``."""
        return _PROBABILITY[move.kernel](self, world, move)

    def _draw_add(self, world: World, chooser: Chooser) -> Move | None:
        if not self._sets:
            return None
        rects, weights = self._sets[chooser.pick(self._set_shares) if len(self._sets) > 1 else 0]
        rect = rects[chooser.pick(weights)]
        if rect in world.units.values():
            return None
        return Move(Kernel.ADD, added=(rect,), window=(rect,))

    def _p_add(self, world: World, move: Move) -> float:
        rect = move.added[0]
        return 0.0 if rect in world.units.values() else self._cand_prob.get(rect, 0.0)

    def _draw_remove(self, world: World, chooser: Chooser) -> Move | None:
        if not world.units:
            return None
        ids, b = self._b_all(world)
        uid = ids[chooser.pick(b)]
        return Move(Kernel.REMOVE, removed=(uid,), window=(world.units[uid],))

    def _p_remove(self, world: World, move: Move) -> float:
        ids, b = self._b_all(world)
        return float(b[ids.index(move.removed[0])] / b.sum())

    def _draw_split(self, world: World, chooser: Chooser) -> Move | None:
        if not world.units:
            return None
        ids = list(world.units)
        uid = ids[chooser.pick(np.ones(len(ids)))]
        rect = world.units[uid]
        axes, pos, w = self.splits(rect)
        if not len(w):
            return None
        k = chooser.pick(w)
        a, b = split_rect(rect, int(axes[k]), int(pos[k]), self.settings.wall_cells)
        big, small = (a, b) if a.rows * a.cols >= b.rows * b.cols else (b, a)
        return Move(Kernel.SPLIT, removed=(uid,), added=(big, small), detail=(int(axes[k]), int(pos[k])),
                    window=(self._band(rect, int(axes[k]), int(pos[k])),))

    def _band(self, rect: Rect, axis: int, position: int) -> Rect:
        t = self.settings.wall_cells
        if axis == 0:
            return Rect(position, position + t - 1, rect.c0, rect.c1)
        return Rect(rect.r0, rect.r1, position, position + t - 1)

    def _p_split(self, world: World, move: Move) -> float:
        rect = world.units[move.removed[0]]
        axes, pos, w = self.splits(rect)
        hit = (axes == move.detail[0]) & (pos == move.detail[1])
        if not hit.any():
            return 0.0
        return float(w[hit].sum() / w.sum()) / len(world.units)

    def merged(self, a: Rect, b: Rect) -> tuple[Rect, int, int] | None:
        """The unit that ``a`` and ``b`` form when they tile a rectangle sharing a wall, with axis and position."""
        t = self.settings.wall_cells
        if a.c0 == b.c0 and a.c1 == b.c1:
            top, low = (a, b) if a.r0 < b.r0 else (b, a)
            if top.r1 - t + 1 == low.r0:
                return Rect(top.r0, low.r1, a.c0, a.c1), 0, low.r0
        if a.r0 == b.r0 and a.r1 == b.r1:
            left, right = (a, b) if a.c0 < b.c0 else (b, a)
            if left.c1 - t + 1 == right.c0:
                return Rect(a.r0, a.r1, left.c0, right.c1), 1, right.c0
        return None

    def _draw_merge(self, world: World, chooser: Chooser) -> Move | None:
        if len(world.units) < 2:
            return None
        ids = list(world.units)
        u = ids[chooser.pick(np.ones(len(ids)))]
        others, w = self._pair_weights(world, u)
        v = others[chooser.pick(w)]
        m = self.merged(world.units[u], world.units[v])
        if m is None:
            return None
        rect, axis, pos = m
        return Move(Kernel.MERGE, removed=(u, v), added=(rect,), detail=(axis, pos),
                    window=(self._band(rect, axis, pos),))

    def _p_merge(self, world: World, move: Move) -> float:
        return self._pair_probability(world, move.removed[0], move.removed[1])

    def _draw_shift(self, kernel: Kernel, world: World, chooser: Chooser) -> Move | None:
        if not world.units:
            return None
        ids, b = self._b_all(world)
        uid = ids[chooser.pick(b)]
        rect = world.units[uid]
        side = Side(chooser.pick(self.wall_v(rect)))
        cells = chooser.pick(self._shift) + 1
        new = moved(rect, side, cells if kernel is Kernel.SHRINK else -cells)
        if not self.valid(new):
            return None
        return Move(kernel, removed=(uid,), added=(new,), detail=(int(side), cells), window=(self._strip(rect, new),))

    def _strip(self, old: Rect, new: Rect) -> Rect:
        """The cells that differ between two rectangles differing in one side (plus that wall's band)."""
        t = self.settings.wall_cells
        u = old.union(new)
        if old.r0 != new.r0:
            return u._replace(r1=min(max(old.r0, new.r0) + t - 1, u.r1))
        if old.r1 != new.r1:
            return u._replace(r0=max(min(old.r1, new.r1) - t + 1, u.r0))
        if old.c0 != new.c0:
            return u._replace(c1=min(max(old.c0, new.c0) + t - 1, u.c1))
        return u._replace(c0=max(min(old.c1, new.c1) - t + 1, u.c0))

    def _p_shift(self, world: World, move: Move) -> float:
        ids, b = self._b_all(world)
        uid = move.removed[0]
        v = self.wall_v(world.units[uid])
        side, cells = move.detail
        return float(b[ids.index(uid)] / b.sum() * v[side] / v.sum() * self._shift[cells - 1])

    def _draw_allocate(self, world: World, chooser: Chooser) -> Move | None:
        rects, w = self.doors(world)
        if not rects:
            return None
        door = rects[chooser.pick(w)]
        if door in world.doors or any(door.intersects(d) for d in world.doors):
            return None
        return Move(Kernel.ALLOCATE, door_added=door, window=(door,))

    def _p_allocate(self, world: World, move: Move) -> float:
        rects, w = self.doors(world)
        door = move.door_added
        if door is None or door not in rects:
            return 0.0
        return float(w[rects.index(door)] / w.sum())

    def _door_z(self, world: World) -> tuple[list[Rect], npt.NDArray[np.float64]]:
        doors = sorted(world.doors)
        z = [_inverse_weight(self.evidence.free(d) / (d.rows * d.cols), self.settings.h_g) for d in doors]
        return doors, np.array(z, np.float64)

    def _draw_delete(self, world: World, chooser: Chooser) -> Move | None:
        if not world.doors:
            return None
        doors, z = self._door_z(world)
        door = doors[chooser.pick(z)]
        return Move(Kernel.DELETE, door_removed=door, window=(door,))

    def _p_delete(self, world: World, move: Move) -> float:
        doors, z = self._door_z(world)
        return float(z[doors.index(move.door_removed)] / z.sum()) if move.door_removed in world.doors else 0.0

    def _draw_interchange(self, world: World, chooser: Chooser) -> Move | None:
        if len(world.units) < 2:
            return None
        ids = list(world.units)
        u = ids[chooser.pick(np.ones(len(ids)))]
        others, w = self._pair_weights(world, u)
        v = others[chooser.pick(w)]
        a, b = world.units[u], world.units[v]
        swapped = interchange(a, b, self.settings.wall_cells)
        if swapped is None or not all(self.valid(r) for r in swapped):
            return None
        return Move(Kernel.INTERCHANGE, removed=(u, v), added=swapped, window=(a.union(b),))

    def _p_interchange(self, world: World, move: Move) -> float:
        return self._pair_probability(world, move.removed[0], move.removed[1])


_DRAW: dict[Kernel, Callable[[Proposer, World, Chooser], Move | None]] = {
    Kernel.ADD: Proposer._draw_add,
    Kernel.REMOVE: Proposer._draw_remove,
    Kernel.SPLIT: Proposer._draw_split,
    Kernel.MERGE: Proposer._draw_merge,
    Kernel.SHRINK: lambda p, w, c: p._draw_shift(Kernel.SHRINK, w, c),
    Kernel.DILATE: lambda p, w, c: p._draw_shift(Kernel.DILATE, w, c),
    Kernel.INTERCHANGE: Proposer._draw_interchange,
    Kernel.ALLOCATE: Proposer._draw_allocate,
    Kernel.DELETE: Proposer._draw_delete,
}

_PROBABILITY: dict[Kernel, Callable[[Proposer, World, Move], float]] = {
    Kernel.ADD: Proposer._p_add,
    Kernel.REMOVE: Proposer._p_remove,
    Kernel.SPLIT: Proposer._p_split,
    Kernel.MERGE: Proposer._p_merge,
    Kernel.SHRINK: Proposer._p_shift,
    Kernel.DILATE: Proposer._p_shift,
    Kernel.INTERCHANGE: Proposer._p_interchange,
    Kernel.ALLOCATE: Proposer._p_allocate,
    Kernel.DELETE: Proposer._p_delete,
}


def apply_move(world: World, move: Move) -> tuple[World, list[int]]:
    """The world after ``move`` and the ids of its added units (removed ids are reused in order)."""
    out = world.copy()
    for uid in move.removed:
        del out.units[uid]
    new_ids: list[int] = []
    for k, rect in enumerate(move.added):
        if k < len(move.removed):
            uid = move.removed[k]
        else:
            uid = out.next_id
            out.next_id += 1
        out.units[uid] = rect
        new_ids.append(uid)
    if move.door_removed is not None:
        out.doors.discard(move.door_removed)
    if move.door_added is not None:
        out.doors.add(move.door_added)
    return out, new_ids


def reverse_move(move: Move, before: World, new_ids: list[int]) -> Move:
    """The move that takes the world after ``move`` back to ``before``."""
    kernel = REVERSE[move.kernel]
    removed = tuple(new_ids)
    added = tuple(before.units[u] for u in move.removed)
    return Move(kernel, removed=removed, added=added, door_added=move.door_removed, door_removed=move.door_added,
                detail=move.detail, window=move.window)


# --- INTERCHANGE geometry ------------------------------------------------------------------------------

_Transform = Callable[[Rect], Rect]


def _flip_rows(r: Rect) -> Rect:
    return Rect(-r.r1, -r.r0, r.c0, r.c1)


def _flip_cols(r: Rect) -> Rect:
    return Rect(r.r0, r.r1, -r.c1, -r.c0)


def _transpose(r: Rect) -> Rect:
    return Rect(r.c0, r.c1, r.r0, r.r1)


def _symmetries() -> list[tuple[_Transform, _Transform]]:
    """The 8 symmetries of the square grid as (forward, inverse) pairs."""
    out: list[tuple[_Transform, _Transform]] = []
    for tr in (False, True):
        for fr in (False, True):
            for fc in (False, True):
                def fwd(r: Rect, tr: bool = tr, fr: bool = fr, fc: bool = fc) -> Rect:
                    r = _transpose(r) if tr else r
                    r = _flip_rows(r) if fr else r
                    return _flip_cols(r) if fc else r

                def inv(r: Rect, tr: bool = tr, fr: bool = fr, fc: bool = fc) -> Rect:
                    r = _flip_cols(r) if fc else r
                    r = _flip_rows(r) if fr else r
                    return _transpose(r) if tr else r

                out.append((fwd, inv))
    return out


_SYMMETRIES = _symmetries()


def _canonical_interchange(a: Rect, b: Rect, t: int) -> tuple[Rect, Rect] | None:
    """``a`` above ``b`` sharing a wall, left sides flush, ``b`` narrower: cut the L the other way."""
    if b.r0 != a.r1 - t + 1 or b.c0 != a.c0 or b.c1 >= a.c1:
        return None
    return Rect(a.r0, b.r1, a.c0, b.c1), Rect(a.r0, a.r1, b.c1 - t + 1, a.c1)


def interchange(a: Rect, b: Rect, wall_cells: int) -> tuple[Rect, Rect] | None:
    """The other cut of the L-shaped union of two units (fig. 3.19), as (new a, new b), or None.

    ``a``'s id goes to the part that keeps ``a``'s far corner.
    """
    t = wall_cells
    if not (a.r1 - t + 1 == b.r0 or b.r1 - t + 1 == a.r0 or a.c1 - t + 1 == b.c0 or b.c1 - t + 1 == a.c0):
        return None  # no shared wall line: no symmetry can bring them to the canonical case (cheap early out)
    for fwd, inv in _SYMMETRIES:
        for x, y, swap in ((a, b, False), (b, a, True)):
            out = _canonical_interchange(fwd(x), fwd(y), wall_cells)
            if out is not None:
                p, q = inv(out[0]), inv(out[1])
                return (q, p) if swap else (p, q)
    return None
