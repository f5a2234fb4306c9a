"""The load-scene stage's data: rack bays, 3D box estimates at rack faces, scene graphs and bin occupancy.

Seed 003, chapter 4 builds a scene graph of stacked objects from 6D pose estimates; here the scene is one rack
bay (a beam pair per level, the floor at level 0), the objects are pallets, loads on them and the beams, and
the answers are which bin holds what. These types are what the estimation (depth image -> boxes), the inference
(boxes + depth -> scene graph) and the store/API share.

Frames: every position is map-frame metres, z up from the floor; a box's ``yaw_rad`` turns its ``size[0]`` axis
from the map x axis. A bay's ``yaw_rad`` is the direction from the aisle into the rack (the fork's direction).
"""

from __future__ import annotations

import enum
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

XYZ = tuple[float, float, float]
"""(x, y, z) in map-frame metres."""


class ObjectKind(enum.StrEnum):
    """What a box in a rack bay is."""

    PALLET = "pallet"
    LOAD = "load"
    """Cartons, boxes or goods standing on a pallet."""
    BEAM = "beam"
    """A rack beam pair of one level (the support a pallet rests on); level 0 has the floor instead."""


class Occupancy(enum.StrEnum):
    """A bin's state as the robots saw it."""

    EMPTY = "empty"
    OCCUPIED = "occupied"
    UNKNOWN = "unknown"
    """Not seen well enough (never in view, or the evidence does not decide)."""


class Relation(enum.StrEnum):
    """Edges of a bay's scene graph (seed 003 table 4.3, adapted to racks)."""

    SUPPORTS = "supports"
    """The source stably holds the target up (beam -> pallet, pallet -> load, load -> load)."""
    UNSTABLE_CONTACT = "unstable_contact"
    """The two touch but neither stably holds the other (a leaning or overhanging load)."""


class Flag(enum.StrEnum):
    """Node flags of a scene graph."""

    FALSE_ESTIMATE = "false_estimate"
    """A detected box the evidence and context reject (a ghost)."""
    HIDDEN_BELOW = "hidden_below"
    """A box nobody detected, added because something else would hover (or a second-deep pallet seen behind
    a gap)."""


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


@dataclass(frozen=True, slots=True)
class SceneNode:
    """One object of a bay's scene graph (a box estimate, possibly corrected, or an added hidden object)."""

    id: str
    kind: ObjectKind
    centre: XYZ
    size: XYZ
    yaw_rad: float
    level: int | None
    flags: frozenset[Flag] = frozenset()
    probability: float = 1.0
    """Posterior probability that the object is there as described."""


@dataclass(frozen=True, slots=True)
class SceneEdge:
    source: str
    target: str
    relation: Relation
    probability: float = 1.0


@dataclass(frozen=True, slots=True)
class SceneGraph:
    """What stands in one bay and what holds what."""

    bay: str
    nodes: tuple[SceneNode, ...]
    edges: tuple[SceneEdge, ...]
    stamp_ns: int
    iterations: int = 0
    """MCMC iterations the inference ran."""


@dataclass(frozen=True, slots=True)
class BinOccupancy:
    """One bin's state: empty, occupied by which objects, or unknown; how sure, and when last seen."""

    bin_id: str
    state: Occupancy
    confidence: float
    """Probability of ``state`` in [0, 1]."""
    last_seen_ns: int | None
    objects: tuple[str, ...] = ()
    """Ids of the scene nodes in the bin (pallet first)."""
    views: int = 0
    """How many separate views of the bin the state rests on."""
    stable: bool | None = None
    """False when a load in the bin has an unstable contact; None when empty or unknown."""
    hidden: bool = False
    """True when an object in the bin was inferred, not seen (e.g. a second-deep pallet)."""
    bay: str | None = None
    detail: dict[str, object] = field(default_factory=dict)
