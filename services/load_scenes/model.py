"""The load-scene stage's data: rack bays, 3D box estimates at rack faces, scene graphs and bin occupancy.

Seed 003, chapter 4 builds a scene graph of stacked objects from 6D pose estimates; here the scene is one rack
bay (a beam pair per level, the floor at level 0), the objects are pallets, loads on them and the beams, and
the answers are which bin holds what. These types are what the estimation (depth image -> boxes), the inference
(boxes + depth -> scene graph) and the store/API share; the outputs the store and the API read too (object kinds,
occupancy, relations, flags, scene graphs and bin occupancy) live in :mod:`shared.loads` and are re-exported here.

Frames: every position is map-frame metres, z up from the floor; a box's ``yaw_rad`` turns its ``size[0]`` axis
from the map x axis. A bay's ``yaw_rad`` is the direction from the aisle into the rack (the fork's direction).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from shared.loads import (
    XYZ,
    BinOccupancy,
    Flag,
    ObjectKind,
    Occupancy,
    Relation,
    SceneEdge,
    SceneGraph,
    SceneNode,
)


@dataclass(frozen=True, slots=True)
class Bay:
    """One rack bay as the rack model gives it: a front opening facing an aisle and its levels.

    ``origin`` is the middle of the bay's front edge on the floor; the bay spans ``width_m`` along the front and
    ``depth_m`` into the rack along ``yaw_rad`` (twice a pallet for double-deep racks). ``levels_z_m`` holds the
    top of each level's support: 0.0 for the floor, then the beam tops; ``bin_ids[i]`` is the bin at level i.
    """

    key: str
    """``row/bay`` style key, unique in the map (e.g. the row key and the bay number)."""
    row: str
    aisle: int
    bay: int
    origin: tuple[float, float]
    yaw_rad: float
    width_m: float
    depth_m: float
    levels_z_m: tuple[float, ...]
    bin_ids: tuple[str, ...]
    beam_height_m: float = 0.12
    """Vertical size of a beam (its top is the level's z)."""
    deep: int = 1
    """Pallet positions one behind the other (1 single-deep, 2 double-deep)."""


@dataclass(frozen=True, slots=True)
class BoxEstimate:
    """One object's 3D box as the RGB-D estimation gives it, with its uncertainty."""

    id: str
    kind: ObjectKind
    centre: XYZ
    size: XYZ
    """Extent along the box's own x (turned by ``yaw_rad``), y and z, metres."""
    yaw_rad: float
    sigma: XYZ
    """One standard deviation of the centre along map x, y, z, metres (tolerances of the predicates)."""
    sigma_yaw_rad: float
    score: float
    """Detection confidence in [0, 1]."""
    stamp_ns: int
    bay: str | None = None
    """Key of the bay the box sits in, None when it is in none."""
    level: int | None = None


@dataclass(frozen=True, slots=True)
class DepthEvidence:
    """Depth points of one view of a bay, for the likelihood: where the sensor saw a surface and from where."""

    origin: XYZ
    """Camera centre in the map frame."""
    points: npt.NDArray[np.float64]
    """(N, 3) surface points in the map frame (rays from ``origin`` end there)."""
    stamp_ns: int


__all__ = [
    "XYZ",
    "Bay",
    "BinOccupancy",
    "BoxEstimate",
    "DepthEvidence",
    "Flag",
    "ObjectKind",
    "Occupancy",
    "Relation",
    "SceneEdge",
    "SceneGraph",
    "SceneNode",
]
