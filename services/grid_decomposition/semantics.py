"""Human semantics (paper C, Table II): labels, their functionality and connect-ability."""

from __future__ import annotations

import enum
from collections.abc import Mapping
from typing import NamedTuple

from services.grid_decomposition.errors import DecompositionError


class Label(enum.IntEnum):
    """Place labels; the value is the code written to ``labels.png``."""

    NONE = 0
    CORRIDOR = 1
    JUNCTION = 2
    STORAGE = 3
    ROOM = 4
    OPEN_AREA = 5
    UNIDENTIFIED = 6


class Connection(enum.Enum):
    """Attribute of a link between two regions (dual of an edge's cogency)."""

    CONNECTED = "connected"
    STORAGE_ACCESS = "storage_access"
    DOOR = "door"
    DISCONNECTED = "disconnected"


class LabelSemantics(NamedTuple):
    """One row of the label table: what a place is for and which labels it may open onto."""

    functionality: str
    connectable: frozenset[Label]


_DRIVABLE = frozenset({Label.CORRIDOR, Label.JUNCTION, Label.ROOM, Label.OPEN_AREA})

LABEL_TABLE: dict[Label, LabelSemantics] = {
    Label.CORRIDOR: LabelSemantics("drivable & storage access", _DRIVABLE | {Label.STORAGE}),
    Label.JUNCTION: LabelSemantics("drivable & connection", _DRIVABLE),
    Label.STORAGE: LabelSemantics("storage", frozenset({Label.CORRIDOR, Label.OPEN_AREA})),
    Label.ROOM: LabelSemantics("drivable & work", _DRIVABLE),
    Label.OPEN_AREA: LabelSemantics("drivable & storage access", _DRIVABLE | {Label.STORAGE}),
    Label.UNIDENTIFIED: LabelSemantics("-", frozenset()),
    Label.NONE: LabelSemantics("-", frozenset()),
}


def parse_label(name: str) -> Label:
    """A :class:`Label` from its name (``corridor``, ``junction``, ``storage``, ``pallet_cell``...)."""
    key = name.strip().upper().replace(" ", "_").replace("-", "_")
    aliases = {"PALLET_CELL": "STORAGE", "PALLET_CELLS": "STORAGE", "OPEN": "OPEN_AREA", "UNKNOWN": "UNIDENTIFIED"}
    key = aliases.get(key, key)
    try:
        return Label[key]
    except KeyError as err:
        names = ", ".join(label.name.lower() for label in Label)
        raise DecompositionError(f"unknown place label {name!r}; use one of {names}") from err


def link_connection(a: Label, b: Label, *, cogent: bool, door: bool) -> Connection:
    """Connection of a link between places labelled ``a`` and ``b`` (paper C's C(e), C(l)).

    A cogent edge is a physical separation: a door if a doorway was closed on it, else
    disconnected. Otherwise labels that the table does not let connect (unidentified, junction to
    storage) are disconnected, a drivable place next to storage is storage access, and the rest
    are connected.
    """
    if cogent:
        return Connection.DOOR if door else Connection.DISCONNECTED
    if b not in LABEL_TABLE[a].connectable or a not in LABEL_TABLE[b].connectable:
        return Connection.DISCONNECTED
    if Label.STORAGE in (a, b):
        return Connection.STORAGE_ACCESS
    return Connection.CONNECTED


LABEL_TABLE_STAGE = "label_table"
"""Stage name of the map-store revisions that record a person's label-table overrides; the grid
decomposition worker re-labels the map from the newest one."""
LABEL_OVERRIDES_KEY = "label_overrides"
"""Summary key of those revisions: {category as a decimal string: label name}."""


def parse_label_table(raw: Mapping[str, str]) -> dict[int, Label]:
    """``{"0": "corridor", "3": "pallet cell"}`` (category -> label name, as stored) -> {0: CORRIDOR, 3: STORAGE}.

    Raises
    ------
    DecompositionError
        A category that is not a non-negative integer, or a label that is not a place label (``none`` is
        not one a person can choose).
    """
    out: dict[int, Label] = {}
    for key, value in raw.items():
        if not (isinstance(key, str) and key.isdigit() and len(key) <= 6):
            raise DecompositionError(f"category {key!r} must be a non-negative integer, e.g. '3'")
        label = parse_label(str(value))
        if label is Label.NONE:
            raise DecompositionError(f"category {key}: 'none' marks occupied or unknown cells, not a place")
        out[int(key)] = label
    return out
