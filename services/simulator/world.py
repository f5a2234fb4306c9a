"""The simulated world: typed, frozen records of a warehouse and its ground truth.

Geometry is in the map frame, metres and radians; a 3-D object is an oriented box standing on
(or floating above) the floor. Uprights, walls, pallets, forklifts and people are all boxes, so
every sensor model renders one primitive and the ground truth is exact by construction.
"""

from __future__ import annotations

import enum
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, NamedTuple

import numpy as np
import numpy.typing as npt

from shared.vocabulary import PlaceLabel

FloatArray = npt.NDArray[np.float64]


class ObjectClass(enum.IntEnum):
    """What a box is; the value is the class id in rendered label images (0 is the floor)."""

    FLOOR = 0
    WALL = 1
    UPRIGHT = 2
    BEAM = 3
    PALLET = 4
    LOAD = 5
    FORKLIFT = 6
    PERSON = 7
    GATE = 8
    CHARGER = 9


class Boxes(NamedTuple):
    """``n`` oriented boxes.

    ``centre_xy`` (n, 2) metres; ``z_m`` (n, 2) bottom and top heights, metres; ``size_xy`` (n, 2)
    length along the box heading and width across it, metres; ``yaw_rad`` (n,) heading;
    ``kind`` (n,) int8 :class:`ObjectClass`; ``colour`` (n, 3) uint8 RGB.
    """

    centre_xy: FloatArray
    z_m: FloatArray
    size_xy: FloatArray
    yaw_rad: FloatArray
    kind: npt.NDArray[np.int8]
    colour: npt.NDArray[np.uint8]

    def __len__(self) -> int:
        return int(self.yaw_rad.shape[0])

    def take(self, index: npt.NDArray[Any]) -> Boxes:
        """The boxes selected by a boolean mask or index array."""
        return Boxes(*(np.asarray(a)[index] for a in self))

    def corners_xy(self) -> FloatArray:
        """Footprint corners (n, 4, 2), counter-clockwise."""
        c, s = np.cos(self.yaw_rad), np.sin(self.yaw_rad)
        half = 0.5 * self.size_xy
        local = np.array([[1.0, 1.0], [-1.0, 1.0], [-1.0, -1.0], [1.0, -1.0]])[None] * half[:, None, :]
        x = self.centre_xy[:, None, 0] + c[:, None] * local[..., 0] - s[:, None] * local[..., 1]
        y = self.centre_xy[:, None, 1] + s[:, None] * local[..., 0] + c[:, None] * local[..., 1]
        return np.stack([x, y], axis=-1)


def concat_boxes(parts: list[Boxes]) -> Boxes:
    """All boxes of ``parts`` in order (an empty list gives no boxes)."""
    if not parts:
        return empty_boxes()
    return Boxes(*(np.concatenate(arrays) for arrays in zip(*parts, strict=True)))


def empty_boxes() -> Boxes:
    """No boxes."""
    return Boxes(np.zeros((0, 2)), np.zeros((0, 2)), np.zeros((0, 2)), np.zeros(0), np.zeros(0, np.int8),
                 np.zeros((0, 3), np.uint8))


class Uprights(NamedTuple):
    """Rack uprights (pillars): ``xy`` (n, 2) centres, metres; ``ids``; ``row`` (n,) index into rows."""

    xy: FloatArray
    ids: tuple[str, ...]
    row: npt.NDArray[np.int64]


class AreaKind(enum.Enum):
    """Kinds of floor area, with their ground-truth label codes."""

    CORRIDOR = int(PlaceLabel.CORRIDOR)
    JUNCTION = int(PlaceLabel.JUNCTION)
    STORAGE = int(PlaceLabel.STORAGE)
    ROOM = int(PlaceLabel.ROOM)
    OPEN_AREA = int(PlaceLabel.OPEN_AREA)


class Area(NamedTuple):
    """A floor polygon (k, 2) of a kind; corridors carry their width and kind detail."""

    id: str
    kind: AreaKind
    polygon: FloatArray
    detail: Mapping[str, Any]


class RackRow(NamedTuple):
    """One rack row: footprint (4, 2), the aisle it faces and its opening direction."""

    id: str
    aisle: int
    polygon: FloatArray
    front_yaw_rad: float
    """Direction from the rack into its aisle."""
    bays: int
    levels: int


class Bin(NamedTuple):
    """A pallet cell: ``AA-BBB-LL`` id, footprint (4, 2), beam height, access pose in the aisle."""

    id: str
    row: str
    aisle: int
    bay: int
    level: int
    polygon: FloatArray
    z_m: float
    access_pose: tuple[float, float, float]
    """(x, y, yaw) in the aisle centre facing the opening, metres and radians."""
    occupied: bool


class LoadTruth(NamedTuple):
    """Ground truth of one object in a loaded rack bin (see :mod:`services.simulator.loads`).

    ``box`` indexes :attr:`World.boxes`; ``support`` is what holds it up: ``"floor"``, ``"beam"`` (the bin's
    beam pair) or the id of the object below; ``slot`` counts pallet positions across the bay (0 first) and
    ``deep_slot`` into the rack (0 at the aisle); ``behind`` marks a back pallet (and its loads) with a pallet in
    front of it; ``stable`` is False where the load's centre does not stand over its support (a leaning load);
    ``overhang`` where the load reaches past its pallet's edge.
    """

    id: str
    bin_id: str
    kind: ObjectClass
    box: int
    support: str
    slot: int
    deep_slot: int
    behind: bool
    stable: bool
    overhang: bool


class Gate(NamedTuple):
    """A dock gate or door: an opening in a wall from ``a`` to ``b`` (each (x, y))."""

    id: str
    kind: str
    a: tuple[float, float]
    b: tuple[float, float]


class Charger(NamedTuple):
    """A charging station and the pose (x, y, yaw) a robot docks at."""

    id: str
    pose: tuple[float, float, float]


class ActorKind(enum.Enum):
    """Things that move."""

    FORKLIFT = "forklift"
    PERSON = "person"
    PALLET = "pallet"


class Actor(NamedTuple):
    """A dynamic object walking its ``path`` (k, 2) back and forth at ``speed_mps``."""

    id: str
    kind: ActorKind
    path: FloatArray
    speed_mps: float


@dataclass(frozen=True, eq=False)
class World:
    """A warehouse: static boxes, uprights, semantic areas, bins, gates, chargers and actors.

    ``layout`` is the layout mapping the world was built from (see
    :func:`services.simulator.world_from_layout`), kept so the world can be written back as YAML.
    """

    name: str
    outline: FloatArray
    """Interior outline of the building, (k, 2) counter-clockwise, metres."""
    walls: FloatArray
    """Wall segments (m, 2, 2) along the interior outline, gates left out, metres."""
    boxes: Boxes
    uprights: Uprights
    rows: tuple[RackRow, ...]
    areas: tuple[Area, ...]
    bins: tuple[Bin, ...]
    gates: tuple[Gate, ...]
    chargers: tuple[Charger, ...]
    actors: tuple[Actor, ...]
    layout: Mapping[str, Any] = field(default_factory=dict)
    loads: tuple[LoadTruth, ...] = ()
    """Ground truth of the objects in the bins of blocks with a ``loads`` option (empty otherwise)."""

    @property
    def bounds(self) -> tuple[float, float, float, float]:
        """(x_min, y_min, x_max, y_max) of everything, metres."""
        corners = self.boxes.corners_xy().reshape(-1, 2)
        points = np.concatenate([self.outline, corners]) if len(corners) else self.outline
        lo, hi = points.min(axis=0), points.max(axis=0)
        return float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1])
