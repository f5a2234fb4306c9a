"""Context knowledge as a prior (section 3.8): geometry evidence, Markov-logic rules, same-length walls.

Evidence predicates (table 3.3) come from a unit's geometry (table 3.6) and its doors; the query
predicates (table 3.4) are inferred exactly: the four type atoms of one unit span 16 worlds, a pair of
adjacent units with their SaLe atom 512, so each marginal is a weighted sum over all of them (no
Markov-logic library: the ground networks are this small, and exact sums need no sampling).
The rules of table 3.5 are weighted implications; their weights are settings. The prior factor
b(u_p, u_q) of eq. 3.34 penalises adjacent units whose connecting walls differ in length when
p(SaLe) is above a threshold.
"""

from __future__ import annotations

import functools
import itertools
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
import numpy.typing as npt

from services.floor_plan.world import Rect, UnitType, World, in_wall, shared_band


@dataclass(frozen=True)
class ContextSettings:
    """Rule weights (table 3.5), the geometry classifier (table 3.6) and the same-length prior (eq. 3.34)."""

    hall_area_m2: float = 120.0
    corridor_ratio: float = 3.0
    type_rule_weight: float = 2.0
    one_type_weight: float = 3.0
    same_length_rule_weight: float = 1.5
    same_length_threshold: float = 0.6
    same_length_sigma_m: float = 0.5
    prior_weight: float = 1.0


class UnitEvidence(NamedTuple):
    """The evidence predicates of one unit (table 3.3)."""

    room_like: bool
    corridor_like: bool
    hall_like: bool
    multi_door: bool


def geometry_evidence(rect: Rect, doors: int, *, resolution_m: float, settings: ContextSettings) -> UnitEvidence:
    """Table 3.6: big units are hall-like, small elongated ones corridor-like, other small ones room-like."""
    rows, cols = rect.rows * resolution_m, rect.cols * resolution_m
    big = rows * cols >= settings.hall_area_m2
    long_ = max(rows, cols) / max(min(rows, cols), resolution_m) >= settings.corridor_ratio
    return UnitEvidence(not big and not long_, not big and long_, big, doors >= 2)


_TYPES = (UnitType.ROOM, UnitType.CORRIDOR, UnitType.HALL, UnitType.OTHER)
_ASSIGNMENTS = np.array(list(itertools.product((False, True), repeat=4)), bool)  # (16, 4): room, corr, hall, other


def _unit_log_weights(e: UnitEvidence, s: ContextSettings) -> npt.NDArray[np.float64]:
    """Sum of the weights of the satisfied type rules of table 3.5 for each of the 16 type assignments."""
    room, corr, hall, other = _ASSIGNMENTS.T
    w = s.type_rule_weight
    ro, co, ha, mul = e

    def implies(body: bool, head: npt.NDArray[np.bool_]) -> npt.NDArray[np.bool_]:
        return (~np.bool_(body)) | head

    clauses = [
        implies(ha, hall), implies(ha, ~room), implies(ha, ~corr), implies(ha, ~other),
        implies(ro, ~hall), implies(co, ~hall),
        implies(ro and not mul, room), implies(ro and not mul, ~corr), implies(ro and mul, other),
        implies(co and not mul, other), implies(co and mul, corr), implies(co and mul, ~room),
    ]
    satisfied = np.asarray(np.sum(clauses, axis=0), dtype=np.float64)
    one_type = np.asarray(_ASSIGNMENTS.sum(axis=1) == 1, dtype=np.float64)
    out: npt.NDArray[np.float64] = w * satisfied + s.one_type_weight * one_type
    return out


@functools.lru_cache(maxsize=256)
def type_marginals(e: UnitEvidence, s: ContextSettings) -> tuple[float, float, float, float]:
    """P(Room), P(Corr), P(Hall), P(Other) of a unit given its evidence (exact)."""
    lw = _unit_log_weights(e, s)
    p = np.exp(lw - lw.max())
    p /= p.sum()
    m = p @ _ASSIGNMENTS
    return float(m[0]), float(m[1]), float(m[2]), float(m[3])


@functools.lru_cache(maxsize=1024)
def same_length_probability(ep: UnitEvidence, eq: UnitEvidence, s: ContextSettings) -> float:
    """P(SaLe(p, q)) of two adjacent units (exact over both units' type atoms and the SaLe atom).

    The pair rules of table 3.5 are grounded both ways round (SaLe is symmetric).
    """
    room, corr, hall, other = _ASSIGNMENTS.T
    w = s.same_length_rule_weight
    both_rooms = np.outer(room, room)
    excluded = np.zeros((16, 16), np.float64)  # how many "A(p) and B(q) -> not SaLe" bodies hold
    for a, b in ((room, hall), (room, corr), (hall, corr), (other, hall), (other, corr), (other, room)):
        excluded += np.outer(a, b) + np.outer(b, a)
    n_excl = 12.0
    sale_true = w * (2.0 + (n_excl - excluded))  # rooms rule satisfied; excluding rules violated where bodies hold
    sale_false = w * (2.0 * (1.0 - both_rooms) + n_excl)
    base = _unit_log_weights(ep, s)[:, None] + _unit_log_weights(eq, s)[None, :]
    joint = np.stack([base + sale_true, base + sale_false])
    joint = np.exp(joint - joint.max())
    return float(joint[0].sum() / joint.sum())


class UnitSemantics(NamedTuple):
    unit_type: UnitType
    probability: float
    evidence: UnitEvidence


class ContextPrior:
    """log p(U | T, R) of eq. 3.33 (up to its constant), incrementally over the units a move touches."""

    def __init__(self, *, resolution_m: float, wall_cells: int, settings: ContextSettings) -> None:
        self.resolution_m = resolution_m
        self.wall_cells = wall_cells
        self.settings = settings

    def _evidence(self, world: World, uid: int) -> UnitEvidence:
        rect = world.units[uid]
        r0, r1, c0, c1 = rect
        doors = sum(1 for d in world.doors  # the bounds test first: most doors are elsewhere
                    if r0 <= d.r0 and d.r1 <= r1 and c0 <= d.c0 and d.c1 <= c1 and in_wall(rect, d, self.wall_cells))
        return geometry_evidence(rect, doors, resolution_m=self.resolution_m, settings=self.settings)

    def _pair_term(self, world: World, p: int, q: int, band: Rect, evidence: dict[int, UnitEvidence]) -> float:
        """The same-length term of adjacent units ``p`` and ``q``; ``evidence`` memoises :meth:`_evidence` by unit."""
        s = self.settings
        for u in (p, q):
            if u not in evidence:
                evidence[u] = self._evidence(world, u)
        if same_length_probability(evidence[p], evidence[q], s) <= s.same_length_threshold:
            return 0.0
        a, b = world.units[p], world.units[q]
        along_rows = band.rows > band.cols
        d = abs((a.rows - b.rows) if along_rows else (a.cols - b.cols)) * self.resolution_m
        return -s.prior_weight * d * d / (2 * s.same_length_sigma_m**2)

    def neighbours(self, world: World, uid: int) -> list[tuple[int, Rect]]:
        rect = world.units[uid]
        t = self.wall_cells
        top, bottom, left, right = rect.r0, rect.r1 - t + 1, rect.c0, rect.c1 - t + 1
        out = []
        for other, r in world.units.items():
            # shared_band's own first test (walls stacked or side by side), inlined: most units fail it
            if other != uid and (bottom == r.r0 or r.r1 - t + 1 == top or right == r.c0 or r.c1 - t + 1 == left):
                band = shared_band(rect, r, t)
                if band is not None:
                    out.append((other, band))
        return out

    def local(self, world: World, ids: set[int]) -> float:
        """The sum of the pair terms that involve any unit in ``ids``."""
        if self.settings.prior_weight == 0:
            return 0.0
        seen: set[tuple[int, int]] = set()
        evidence: dict[int, UnitEvidence] = {}
        total = 0.0
        for uid in ids:
            if uid not in world.units:
                continue
            for other, band in self.neighbours(world, uid):
                key = (min(uid, other), max(uid, other))
                if key not in seen:
                    seen.add(key)
                    total += self._pair_term(world, uid, other, band, evidence)
        return total

    def total(self, world: World) -> float:
        return self.local(world, set(world.units))

    def semantics(self, world: World) -> dict[int, UnitSemantics]:
        """The most probable type of every unit and its marginal probability."""
        out: dict[int, UnitSemantics] = {}
        for uid in world.units:
            e = self._evidence(world, uid)
            m = type_marginals(e, self.settings)
            k = int(np.argmax(m))
            out[uid] = UnitSemantics(_TYPES[k], m[k], e)
        return out
