"""The storage bin record: what the pillar stage writes as a ``bin`` feature and everyone else reads back.

:meth:`Bin.feature` makes the map-store :class:`~shared.store.Feature` of a bin (its properties in the order
the store has always held them), :meth:`Bin.from_feature` reads one back. Reading is lenient about the
properties, as bins written by other stages or older versions may lack some: a property that is missing or
of the wrong type reads as None (the centre falls back to the middle of the geometry's bounds).

Examples
--------
>>> record = Bin(id="03-014", aisle=3, bay=14, centre=(41.2, 17.6))
>>> Bin.from_feature(record.feature()) == record
True
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, NamedTuple

from shared.store import Feature, StoreError
from shared.store.records import bounds
from shared.vocabulary import FeatureKind

XY = tuple[float, float]
"""(x, y) in map-frame metres."""

ID_FORMAT = "`AA-BBB` (aisle, bay), or `AA-BBB-LL` (LL = level + 1, `01` the floor) where the site's rack profiles " \
            "give levels"
"""Aisle's bin ids in words (documentation and API schema)."""
ID_PATTERN = r"^(\d{2,})-(\d{3,})(?:-(\d{2,}))?$"
"""Aisle's bin ids (:data:`ID_FORMAT`); the groups are aisle, bay and level + 1."""


class BinError(ValueError):
    """A feature that is not a storage bin, or a bin record that cannot be stored."""


class AccessPose(NamedTuple):
    """Where a vehicle stands in the aisle to reach a bin: position in metres, heading facing the opening."""

    x_m: float
    y_m: float
    yaw_rad: float
    """Radians from the map x axis."""


class Opening(NamedTuple):
    """The front edge a fork enters a bin by: its two ends (x, y) in metres and the clear width between them."""

    left: XY
    right: XY
    width_m: float


@dataclass(frozen=True, slots=True)
class Bin:
    """One storage bin (pallet cell) of the map.

    Parameters
    ----------
    id : str
        Aisle's id of the bin, ``AA-BBB`` (aisle, bay), with ``-LL`` (level + 1) when levels are known; also
        the key of its feature.
    centre : (x, y)
        Middle of the bin, map-frame metres.
    aisle, bay : int, optional
        Aisle and bay numbers.
    level : int, optional
        Shelf level, 0 the floor; None while unknown.
    z_m : float, optional
        Height of the bin's floor (beam top), metres; None while unknown.
    footprint : sequence of (x, y), optional
        Polygon ring in metres (closed: first point repeated last), front edge first; None for a point bin.
    access_pose : AccessPose, optional
        Where a vehicle stands to reach the bin.
    row, back_row : str, optional
        Keys of the aisle-facing rack row and of the row behind the bin.
    confidence : float, optional
        The stage's confidence in the bin, 0..1.
    """

    id: str
    centre: XY
    aisle: int | None = None
    bay: int | None = None
    level: int | None = None
    z_m: float | None = None
    footprint: tuple[XY, ...] | None = None
    access_pose: AccessPose | None = None
    row: str | None = None
    back_row: str | None = None
    confidence: float | None = None

    def __post_init__(self) -> None:
        if not self.id:
            raise BinError("a bin needs an id")

    @property
    def opening(self) -> Opening | None:
        """The front edge (the footprint's first side), or None without a footprint."""
        if self.footprint is None or len(self.footprint) < 3:
            return None
        left, right = self.footprint[0], self.footprint[1]
        return Opening(left, right, float(math.hypot(right[0] - left[0], right[1] - left[1])))

    @property
    def reach(self) -> XY:
        """Where the bin is reached from: the access pose's position, else the centre (metres)."""
        return self.centre if self.access_pose is None else (self.access_pose.x_m, self.access_pose.y_m)

    def feature(self) -> Feature:
        """The map-store ``bin`` feature of the bin (a polygon with a footprint, else a point at the centre).

        Raises
        ------
        BinError
            The store refuses the geometry (non-finite coordinates).
        """
        geometry: dict[str, Any] = (
            {"type": "Point", "coordinates": list(self.centre)} if self.footprint is None
            else {"type": "Polygon", "coordinates": [[list(point) for point in self.footprint]]})
        properties = {
            "kind": FeatureKind.BIN.value,
            "id": self.id,
            "aisle": self.aisle,
            "bay": self.bay,
            "level": self.level,
            "z_m": self.z_m,
            "access_pose": None if self.access_pose is None else list(self.access_pose),
            "row": self.row,
            "back_row": self.back_row,
            "centre": list(self.centre),
        }
        try:
            return Feature(FeatureKind.BIN.value, self.id, geometry, properties, self.confidence)
        except StoreError as err:
            raise BinError(f"bin {self.id!r}: {err}") from err

    @classmethod
    def from_feature(cls, feature: Feature) -> Bin:
        """The bin a stored ``bin`` feature describes; properties missing or of the wrong type read as None.

        The id is the ``id`` property, else the feature's key; the centre the ``centre`` property, else the
        middle of the geometry's bounds; the footprint the ring of a Polygon geometry.

        Raises
        ------
        BinError
            The feature is not of kind ``bin``.
        """
        if feature.kind != FeatureKind.BIN:
            raise BinError(f"feature {feature.kind}/{feature.key} is not a bin")
        properties = feature.properties
        centre = _xy(properties.get("centre"))
        if centre is None:
            min_x, min_y, max_x, max_y = bounds(feature.geometry)
            centre = ((min_x + max_x) / 2.0, (min_y + max_y) / 2.0)
        return cls(
            id=_str(properties.get("id")) or feature.key,
            centre=centre,
            aisle=_int(properties.get("aisle")),
            bay=_int(properties.get("bay")),
            level=_int(properties.get("level")),
            z_m=_float(properties.get("z_m")),
            footprint=_footprint(feature.geometry),
            access_pose=_pose(properties.get("access_pose")),
            row=_str(properties.get("row")),
            back_row=_str(properties.get("back_row")),
            confidence=feature.confidence,
        )


def _number(value: Any) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool)


def _int(value: Any) -> int | None:
    return value if isinstance(value, int) and not isinstance(value, bool) else None


def _float(value: Any) -> float | None:
    return float(value) if _number(value) else None


def _str(value: Any) -> str | None:
    return value if isinstance(value, str) else None


def _xy(value: Any) -> XY | None:
    if isinstance(value, Sequence) and not isinstance(value, str) and len(value) == 2 and all(map(_number, value)):
        return float(value[0]), float(value[1])
    return None


def _pose(value: Any) -> AccessPose | None:
    if isinstance(value, Sequence) and not isinstance(value, str) and len(value) == 3 and all(map(_number, value)):
        return AccessPose(float(value[0]), float(value[1]), float(value[2]))
    return None


def _footprint(geometry: Mapping[str, Any]) -> tuple[XY, ...] | None:
    """The ring of a Polygon geometry (its outer ring, as given), or None for any other geometry."""
    if geometry.get("type") != "Polygon" or not geometry.get("coordinates"):
        return None
    ring = [_xy(point) for point in geometry["coordinates"][0]]
    points = [point for point in ring if point is not None]
    return tuple(points) if len(points) == len(ring) else None


__all__ = ["ID_FORMAT", "ID_PATTERN", "XY", "AccessPose", "Bin", "BinError", "Opening"]
