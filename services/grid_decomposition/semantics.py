"""Human semantics (paper C, Table II): what each place label is for and which labels it connects to.

The labels themselves are :class:`shared.vocabulary.PlaceLabel`; their values are the codes of ``labels.png``.
"""

from __future__ import annotations

import enum
from collections.abc import Mapping
from typing import NamedTuple

from services.grid_decomposition.errors import DecompositionError
from shared.vocabulary import PlaceLabel


class Connection(enum.Enum):
    """Attribute of a link between two regions (dual of an edge's cogency)."""

    CONNECTED = "connected"
    STORAGE_ACCESS = "storage_access"
    DOOR = "door"
    DISCONNECTED = "disconnected"


class LabelSemantics(NamedTuple):
    """One row of the label table: what a place is for and which labels it may open onto."""

    functionality: str
    connectable: frozenset[PlaceLabel]


_DRIVABLE = frozenset({PlaceLabel.CORRIDOR, PlaceLabel.JUNCTION, PlaceLabel.ROOM, PlaceLabel.OPEN_AREA})

LABEL_TABLE: dict[PlaceLabel, LabelSemantics] = {
    PlaceLabel.CORRIDOR: LabelSemantics("drivable & storage access", _DRIVABLE | {PlaceLabel.STORAGE}),
    PlaceLabel.JUNCTION: LabelSemantics("drivable & connection", _DRIVABLE),
    PlaceLabel.STORAGE: LabelSemantics("storage", frozenset({PlaceLabel.CORRIDOR, PlaceLabel.OPEN_AREA})),
    PlaceLabel.ROOM: LabelSemantics("drivable & work", _DRIVABLE),
    PlaceLabel.OPEN_AREA: LabelSemantics("drivable & storage access", _DRIVABLE | {PlaceLabel.STORAGE}),
    PlaceLabel.UNIDENTIFIED: LabelSemantics("-", frozenset()),
    PlaceLabel.NONE: LabelSemantics("-", frozenset()),
}


def parse_label(name: str) -> PlaceLabel:
    """A :class:`PlaceLabel` from its name (``corridor``, ``junction``, ``storage``, ``pallet_cell``...)."""
    key = name.strip().upper().replace(" ", "_").replace("-", "_")
    aliases = {"PALLET_CELL": "STORAGE", "PALLET_CELLS": "STORAGE", "OPEN": "OPEN_AREA", "UNKNOWN": "UNIDENTIFIED"}
    key = aliases.get(key, key)
    try:
        return PlaceLabel[key]
    except KeyError as err:
        names = ", ".join(label.name.lower() for label in PlaceLabel)
        raise DecompositionError(f"unknown place label {name!r}; use one of {names}") from err


def link_connection(a: PlaceLabel, b: PlaceLabel, *, cogent: bool, door: bool) -> Connection:
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
    if PlaceLabel.STORAGE in (a, b):
        return Connection.STORAGE_ACCESS
    return Connection.CONNECTED


LABEL_TABLE_STAGE = "label_table"
"""Stage name of the map-store revisions that record a person's label-table overrides; the grid
decomposition worker re-labels the map from the newest one."""
LABEL_OVERRIDES_KEY = "label_overrides"
"""Summary key of those revisions: {category as a decimal string: label name}."""


def parse_label_table(raw: Mapping[str, str]) -> dict[int, PlaceLabel]:
    """``{"0": "corridor", "3": "pallet cell"}`` (category -> label name, as stored) -> {0: CORRIDOR, 3: STORAGE}.

    Raises
    ------
    DecompositionError
        A category that is not a non-negative integer, or a label that is not a place label (``none`` is
        not one a person can choose).
    """
    out: dict[int, PlaceLabel] = {}
    for key, value in raw.items():
        if not (isinstance(key, str) and key.isdigit() and len(key) <= 6):
            raise DecompositionError(f"category {key!r} must be a non-negative integer, e.g. '3'")
        label = parse_label(str(value))
        if label is PlaceLabel.NONE:
            raise DecompositionError(f"category {key}: 'none' marks occupied or unknown cells, not a place")
        out[int(key)] = label
    return out
