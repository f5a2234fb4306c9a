"""The map's vocabulary: feature kinds, layer names, place labels and semantic classes.

Every part of Aisle names these the same way; the string values are what the store, the API and the
exports carry, so they never change once released.
"""

from __future__ import annotations

import enum
from typing import Final

REVISION_HEADER: Final = "X-Aisle-Revision-Id"
"""HTTP response header naming the revision a read covers."""


class FeatureKind(enum.StrEnum):
    """Kinds of stored map features (``Feature.kind``)."""

    WALL = "wall"
    LINE = "line"
    """A line of the decomposition's cell arrangement."""
    CORRIDOR = "corridor"
    """A corridor region of the decomposition, or an aisle between rack rows (key ``aisle-NN``)."""
    JUNCTION = "junction"
    ROOM = "room"
    OPEN_AREA = "open_area"
    REGION = "region"
    """A region without a kind of its own (storage, unidentified); its ``label`` property names it."""
    PILLAR = "pillar"
    RACK_ROW = "rack_row"
    BIN = "bin"
    OBJECT = "object"
    """A dynamic or movable object seen by a camera (pallet, forklift, person)."""
    DOCK = "dock"
    GATE = "gate"
    CHARGER = "charger"
    ROBOT = "robot"
    """A robot heard on the bus: its latest pose and its track over the last minute (``shared.robots``)."""
    UNIT = "unit"
    """A space unit of the floor plan: a rectangle with walls, typed room, corridor, hall or other."""
    DOOR = "door"
    """A door of the floor plan: an opening in the wall two units share."""
    OBSTACLE = "obstacle"
    """A solid block of the map (a rack drawn solid, a filled outside) the floor plan keeps out of its units."""
    BIN_STATE = "bin_state"
    """What the robots saw in a bin (empty, occupied by which objects, unknown), keyed by the bin's id
    (``shared.loads``)."""
    LOAD_SCENE = "load_scene"
    """The scene graph of a rack bay (objects, supports, unstable contacts, false and hidden objects), keyed by the
    bay (``shared.loads``)."""


REGION_KINDS: Final = (FeatureKind.CORRIDOR, FeatureKind.JUNCTION, FeatureKind.ROOM, FeatureKind.OPEN_AREA,
                       FeatureKind.REGION)
"""Feature kinds of the place regions the grid decomposition writes."""

PLACE_KINDS: Final = (FeatureKind.DOCK, FeatureKind.GATE, FeatureKind.CHARGER)
"""Feature kinds of the places operators set through the API."""


class LayerName(enum.StrEnum):
    """Default names of the grid layers the stages write (each is a setting of its stage)."""

    OCCUPANCY = "occupancy"
    PLACE_LABELS = "place_labels"
    PLACE_SEGMENTS = "place_segments"
    SEMANTIC_LABEL = "semantic_label"
    SEMANTIC_ENTROPY = "semantic_entropy"
    FLOOR_PLAN = "floor_plan"


class PlaceLabel(enum.IntEnum):
    """Place labels of the grid decomposition (papers B and C); the value is the code in the label layer."""

    NONE = 0
    CORRIDOR = 1
    JUNCTION = 2
    STORAGE = 3
    ROOM = 4
    OPEN_AREA = 5
    UNIDENTIFIED = 6


class SemanticClass(enum.IntEnum):
    """Semantic classes of the fusion's label layer; the value is the uint8 code in that layer.

    ``NONE`` (0) marks cells with no evidence; every other class is part of the per-cell distribution.
    """

    NONE = 0
    UNKNOWN = 1
    WALL = 2
    RACK = 3
    PALLET = 4
    GATE = 5
    FORKLIFT = 6
    HUMAN = 7


__all__ = [
    "PLACE_KINDS",
    "REGION_KINDS",
    "REVISION_HEADER",
    "FeatureKind",
    "LayerName",
    "PlaceLabel",
    "SemanticClass",
]
