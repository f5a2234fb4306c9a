"""The parametric world: rectangular units with walls, doors between adjacent units.

Units live in a grid frame (rows, columns) that may be rotated against the map by one angle
(:class:`Frame`); inside that frame every unit is an axis-aligned rectangle of cells. A unit's
rectangle is its *outer* extent: its four walls are the band of ``wall_cells`` cells along the
border, its free space the rest. Two units are adjacent when a wall band of one coincides with a
wall band of the other (they share that wall); a door is a run of cells of such a shared band.
"""

from __future__ import annotations

import enum
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np
import numpy.typing as npt


class Rect(NamedTuple):
    """Inclusive cell bounds ``r0..r1`` (rows) and ``c0..c1`` (columns) of a unit or door."""

    r0: int
    r1: int
    c0: int
    c1: int

    @property
    def rows(self) -> int:
        return self.r1 - self.r0 + 1

    @property
    def cols(self) -> int:
        return self.c1 - self.c0 + 1

    def inner(self, wall_cells: int) -> Rect:
        """The free space inside the walls (may be empty: r0 > r1)."""
        t = wall_cells
        return Rect(self.r0 + t, self.r1 - t, self.c0 + t, self.c1 - t)

    def contains(self, other: Rect) -> bool:
        return self.r0 <= other.r0 and other.r1 <= self.r1 and self.c0 <= other.c0 and other.c1 <= self.c1

    def intersects(self, other: Rect) -> bool:
        return not (other.r1 < self.r0 or self.r1 < other.r0 or other.c1 < self.c0 or self.c1 < other.c0)

    def union(self, other: Rect) -> Rect:
        return Rect(min(self.r0, other.r0), max(self.r1, other.r1), min(self.c0, other.c0), max(self.c1, other.c1))

    def centre(self) -> tuple[float, float]:
        return (self.r0 + self.r1) / 2.0, (self.c0 + self.c1) / 2.0


class Side(enum.IntEnum):
    """The four walls of a unit."""

    TOP = 0  # low rows
    BOTTOM = 1
    LEFT = 2  # low columns
    RIGHT = 3


def wall_band(rect: Rect, side: Side, wall_cells: int) -> Rect:
    """The cells of one wall of ``rect`` (the full side, corners included)."""
    t = wall_cells
    match side:
        case Side.TOP:
            return Rect(rect.r0, rect.r0 + t - 1, rect.c0, rect.c1)
        case Side.BOTTOM:
            return Rect(rect.r1 - t + 1, rect.r1, rect.c0, rect.c1)
        case Side.LEFT:
            return Rect(rect.r0, rect.r1, rect.c0, rect.c0 + t - 1)
        case _:
            return Rect(rect.r0, rect.r1, rect.c1 - t + 1, rect.c1)


def in_wall(rect: Rect, part: Rect, wall_cells: int) -> bool:
    """Whether ``part`` lies in the wall band of ``rect`` (inside it and clear of its free space)."""
    if not rect.contains(part):
        return False
    inner = rect.inner(wall_cells)
    return inner.r0 > inner.r1 or inner.c0 > inner.c1 or not inner.intersects(part)


def moved(rect: Rect, side: Side, inward_cells: int) -> Rect:
    """``rect`` with one wall moved inwards (positive, SHRINK) or outwards (negative, DILATE)."""
    d = inward_cells
    match side:
        case Side.TOP:
            return rect._replace(r0=rect.r0 + d)
        case Side.BOTTOM:
            return rect._replace(r1=rect.r1 - d)
        case Side.LEFT:
            return rect._replace(c0=rect.c0 + d)
        case _:
            return rect._replace(c1=rect.c1 - d)


def shared_band(a: Rect, b: Rect, wall_cells: int) -> Rect | None:
    """The part of a wall ``a`` and ``b`` share (their coinciding wall bands, corners excluded), if any."""
    t = wall_cells
    if a.r1 - t + 1 == b.r0 or b.r1 - t + 1 == a.r0:  # stacked: a above b or b above a
        top = a if a.r0 < b.r0 else b
        lo, hi = max(a.c0, b.c0) + t, min(a.c1, b.c1) - t
        if hi >= lo:
            return Rect(top.r1 - t + 1, top.r1, lo, hi)
    if a.c1 - t + 1 == b.c0 or b.c1 - t + 1 == a.c0:  # side by side
        left = a if a.c0 < b.c0 else b
        lo, hi = max(a.r0, b.r0) + t, min(a.r1, b.r1) - t
        if hi >= lo:
            return Rect(lo, hi, left.c1 - t + 1, left.c1)
    return None


def sharing(rect: Rect, boxes: npt.NDArray[np.int64], wall_cells: int) -> npt.NDArray[np.bool_]:
    """Per row ``r0, r1, c0, c1`` of ``boxes`` (broadcast against ``rect``'s bounds, so ``rect`` may be arrays too):
    whether it shares a wall with ``rect`` (:func:`shared_band` is not None), all at once."""
    t = wall_cells
    r0, r1, c0, c1 = boxes[..., 0], boxes[..., 1], boxes[..., 2], boxes[..., 3]
    stacked = (rect.r1 - t + 1 == r0) | (r1 - t + 1 == rect.r0)
    beside = (rect.c1 - t + 1 == c0) | (c1 - t + 1 == rect.c0)
    cols = np.minimum(rect.c1, c1) - t >= np.maximum(rect.c0, c0) + t
    rows = np.minimum(rect.r1, r1) - t >= np.maximum(rect.r0, r0) + t
    out: npt.NDArray[np.bool_] = (stacked & cols) | (beside & rows)
    return out


class UnitType(enum.StrEnum):
    """Semantic type of a unit (seed 003, eq. 3.29)."""

    ROOM = "room"
    CORRIDOR = "corridor"
    HALL = "hall"
    OTHER = "other"


@dataclass
class World:
    """A world state W: units by id (ids stay with a unit while it only changes shape) and doors.

    Doors are cell rectangles; the two units a door connects are the ones whose walls hold it.
    """

    units: dict[int, Rect] = field(default_factory=dict)
    doors: set[Rect] = field(default_factory=set)
    next_id: int = 1

    def copy(self) -> World:
        return World(dict(self.units), set(self.doors), self.next_id)

    def key(self) -> tuple[frozenset[Rect], frozenset[Rect]]:
        """Identity of the state regardless of ids (for enumeration and tests)."""
        return frozenset(self.units.values()), frozenset(self.doors)

    def door_units(self, door: Rect, wall_cells: int) -> list[int]:
        """Ids of the units whose walls hold ``door``."""
        return [uid for uid, r in self.units.items()  # the bounds test first: most units are elsewhere
                if r.r0 <= door.r0 and door.r1 <= r.r1 and r.c0 <= door.c0 and door.c1 <= r.c1
                and in_wall(r, door, wall_cells)]

    def doors_valid(self, wall_cells: int, near: Sequence[Rect] | None = None) -> bool:
        """Every door lies in the walls of exactly two units.

        With ``near`` (the rectangles a move removed or added) only the doors touching them are looked
        at: the holders of any other door did not change.
        """
        doors = self.doors if near is None else [  # Rect.intersects, inlined
            d for d in self.doors
            if any(not (d.r1 < r.r0 or r.r1 < d.r0 or d.c1 < r.c0 or r.c1 < d.c0) for r in near)]
        return all(len(self.door_units(d, wall_cells)) == 2 for d in doors)
