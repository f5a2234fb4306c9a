"""Route ends as a client writes them (``bin:03-014``, ``dock:G1``, ``point:12.5,4``) and where they are.

A bin's end is its access pose (where a vehicle stands in the aisle); a place's (dock, gate,
charger) is its ``approach_pose`` property, else its ``pose`` property, else the middle of its
geometry; a point is itself.
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from atlas.navigation.errors import EndSyntaxError, NoRouteError, UnknownEndError
from shared.store import Feature, MapStore
from shared.store.records import bounds
from shared.vocabulary import PLACE_KINDS, FeatureKind

KEY_PATTERN = r"^[A-Za-z0-9][A-Za-z0-9._:-]{0,127}$"
"""A bin id or place key (the same rule as bin ids in the bins API)."""
MAX_COORDINATE_M = 100_000.0
"""Largest coordinate accepted in a ``point:`` end; a warehouse is far smaller."""
END_FORMS = ("bin:<WMS id>", "<kind>:<key> or place:<kind>/<key> with kind dock, gate or charger", "point:<x>,<y>")
_KEY = re.compile(KEY_PATTERN)


@dataclass(frozen=True, slots=True)
class End:
    """A parsed end: ``kind`` is ``bin``, a place kind or ``point``; ``key`` for bins and places, ``xy`` for points."""

    text: str
    kind: str
    key: str | None = None
    xy: tuple[float, float] | None = None


@dataclass(frozen=True, slots=True)
class Located:
    """Where an end is: map metres, heading (radians) when the end has one, and a label for messages."""

    end: End
    x_m: float
    y_m: float
    yaw_rad: float | None


def _syntax(text: str, why: str) -> EndSyntaxError:
    return EndSyntaxError(f"route end {text!r}: {why}; write one of: {'; '.join(END_FORMS)}")


def parse_end(text: str) -> End:
    """Parse a route end.

    Raises
    ------
    EndSyntaxError
        Not one of the forms in :data:`END_FORMS`, or a bad key or coordinate.
    """
    prefix, colon, rest = text.partition(":")
    if not colon:
        raise _syntax(text, "it has no 'kind:' prefix")
    if prefix == "point":
        parts = rest.split(",")
        try:
            xy = [float(p) for p in parts]
        except ValueError:
            xy = []
        if len(xy) != 2 or not all(math.isfinite(v) and abs(v) <= MAX_COORDINATE_M for v in xy):
            raise _syntax(text, f"a point needs two finite numbers x,y in metres (at most {MAX_COORDINATE_M:g})")
        return End(text, "point", xy=(xy[0], xy[1]))
    if prefix == "place":
        kind, slash, key = rest.partition("/")
        if not slash:
            raise _syntax(text, "a place is written place:<kind>/<key>")
    else:
        kind, key = prefix, rest
    if kind != FeatureKind.BIN and kind not in PLACE_KINDS:
        raise _syntax(text, f"unknown kind {kind!r}")
    if not _KEY.match(key):
        raise _syntax(text, f"{key!r} is not a valid {kind} key (letters, digits, '.', '_', ':', '-'; 1-128)")
    return End(text, kind, key=key)


def _pose(value: Any) -> tuple[float, float, float | None] | None:
    if not isinstance(value, Sequence) or isinstance(value, str) or len(value) not in (2, 3):
        return None
    if not all(isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v) for v in value):
        return None
    return float(value[0]), float(value[1]), float(value[2]) if len(value) == 3 else None


def geometry_centre(geometry: Mapping[str, Any]) -> tuple[float, float]:
    """The middle of a GeoJSON geometry: a point itself, a polygon's area centroid, anything else (or a polygon
    without area) the middle of its bounds."""
    kind, coords = geometry["type"], geometry["coordinates"]
    if kind == "Point":
        return float(coords[0]), float(coords[1])
    if kind == "Polygon" and coords and len(coords[0]) >= 4:
        ring = np.asarray([point[:2] for point in coords[0]], dtype=float)
        x, y = ring[:, 0], ring[:, 1]
        cross = x[:-1] * y[1:] - x[1:] * y[:-1]
        area = cross.sum() / 2.0
        if abs(area) > 1e-12:
            return (float(((x[:-1] + x[1:]) * cross).sum() / (6.0 * area)),
                    float(((y[:-1] + y[1:]) * cross).sum() / (6.0 * area)))
    min_x, min_y, max_x, max_y = bounds(geometry)
    return (min_x + max_x) / 2.0, (min_y + max_y) / 2.0


def place_pose(feature: Feature) -> tuple[float, float, float | None]:
    """Where a vehicle goes for a place: (x, y, yaw or None), from ``approach_pose``, ``pose`` or the geometry."""
    for name in ("approach_pose", "pose"):
        pose = _pose(feature.properties.get(name))
        if pose is not None:
            return pose
    return (*geometry_centre(feature.geometry), None)


def locate_end(store: MapStore, map_id: int, end: End, *, revision: int | None = None) -> Located:
    """Where ``end`` is on the map as of ``revision``.

    Raises
    ------
    UnknownEndError
        No such bin or place.
    NoRouteError
        A bin without an access pose.
    """
    if end.xy is not None:
        return Located(end, end.xy[0], end.xy[1], None)
    assert end.key is not None
    found = store.feature(map_id, end.kind, end.key, revision=revision)
    if found is None:
        listing = "bins" if end.kind == FeatureKind.BIN else f"places?kind={end.kind}"
        raise UnknownEndError(f"the map has no {end.kind} {end.key!r}; see /v1/maps/<map>/{listing}")
    if end.kind == FeatureKind.BIN:
        pose = _pose(found.feature.properties.get("access_pose"))
        if pose is None:
            raise NoRouteError(f"bin {end.key!r} has no access pose yet, so there is nowhere to drive to for it")
        return Located(end, pose[0], pose[1], pose[2])
    x, y, yaw = place_pose(found.feature)
    return Located(end, x, y, yaw)
