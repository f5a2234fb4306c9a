"""Rack levels: a site's rack profiles turn each floor cell into one bin per beam level.

A downward fisheye sees where the uprights stand, not how high the beams are; a site knows its
racks' beam heights (they are in its racking drawings and its WMS). A :class:`RackProfile` gives
them, for the racks inside an area of the map or, without an area, everywhere else; a bin then
exists per level, its id ``AA-BBB-LL`` with ``LL`` = level + 1 (``01`` the floor), stable across
rebuilds because the floor cell's id is.
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from typing import NamedTuple

import cv2
import numpy as np
import numpy.typing as npt

from services.pillar_mapping.bins import StorageBin
from services.pillar_mapping.errors import PillarMappingError

FloatArray = npt.NDArray[np.float64]


class RackProfile(NamedTuple):
    """Beam heights of a site's racks: ``levels_m`` the height of each storage level's floor, metres, from
    the floor (0.0) up; ``area`` (K, 2) map metres, the polygon the profile applies in, None for everywhere
    no other profile's area covers."""

    levels_m: tuple[float, ...]
    area: FloatArray | None = None


def rack_profile(levels_m: Sequence[float], area: Sequence[Sequence[float]] | None = None) -> RackProfile:
    """A validated :class:`RackProfile`; raises :class:`PillarMappingError` naming what is wrong."""
    levels = tuple(float(z) for z in levels_m)
    increasing = all(b > a for a, b in itertools.pairwise(levels))
    if not levels or not all(np.isfinite(levels)) or levels[0] < 0 or not increasing:
        raise PillarMappingError(f"rack levels must be finite, >= 0 and increasing, got {list(levels_m)}")
    if area is None:
        return RackProfile(levels)
    polygon = np.asarray(area, dtype=np.float64)
    if polygon.ndim != 2 or polygon.shape[1] != 2 or len(polygon) < 3 or not np.all(np.isfinite(polygon)):
        raise PillarMappingError(f"a rack profile's area must be at least 3 finite [x, y] points, got {area}")
    return RackProfile(levels, polygon)


def profile_at(profiles: Sequence[RackProfile], xy: FloatArray) -> RackProfile | None:
    """The profile for a point (2,) metres: the first whose area holds it, else the first without an area."""
    for profile in profiles:
        if profile.area is not None:
            contour = profile.area.astype(np.float32).reshape(-1, 1, 2)
            if cv2.pointPolygonTest(contour, (float(xy[0]), float(xy[1])), False) >= 0:
                return profile
    return next((p for p in profiles if p.area is None), None)


def bins_on_levels(bins: Sequence[StorageBin], profiles: Sequence[RackProfile]) -> list[StorageBin]:
    """One bin per level of each floor cell (``level`` 0 the floor) where a profile covers its centre.

    Cells no profile covers stay as they are: ``level`` and ``z_m`` None, id without a level.
    """
    out: list[StorageBin] = []
    for cell in bins:
        profile = profile_at(profiles, cell.centre)
        if profile is None:
            out.append(cell)
            continue
        out.extend(
            cell._replace(id=f"{cell.id}-{level + 1:02d}", level=level, z_m=z)
            for level, z in enumerate(profile.levels_m)
        )
    return out
