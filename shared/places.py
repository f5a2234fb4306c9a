"""What each place label means (paper C, Table II), and the label table a person sets.

The grid decomposition labels its regions with :class:`~shared.vocabulary.PlaceLabel`; a person may say which
label a place category means (``{"3": "storage"}``). That choice is a map-store revision of stage
:data:`LABEL_TABLE_STAGE` whose summary holds :data:`LABEL_OVERRIDES_KEY`; the API writes it and the
decomposition worker reads it, so both take the table and its parsing from here.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Final, NamedTuple

from shared.vocabulary import PlaceLabel


class PlaceLabelError(ValueError):
    """A name that is not a place label, or a label table that cannot be taken."""


class LabelSemantics(NamedTuple):
    """One row of the label table: what a place is for and which labels it may open onto."""

    functionality: str
    connectable: frozenset[PlaceLabel]


_DRIVABLE = frozenset({PlaceLabel.CORRIDOR, PlaceLabel.JUNCTION, PlaceLabel.ROOM, PlaceLabel.OPEN_AREA})

LABEL_TABLE: Final[dict[PlaceLabel, LabelSemantics]] = {
    PlaceLabel.CORRIDOR: LabelSemantics("drivable & storage access", _DRIVABLE | {PlaceLabel.STORAGE}),
    PlaceLabel.JUNCTION: LabelSemantics("drivable & connection", _DRIVABLE),
    PlaceLabel.STORAGE: LabelSemantics("storage", frozenset({PlaceLabel.CORRIDOR, PlaceLabel.OPEN_AREA})),
    PlaceLabel.ROOM: LabelSemantics("drivable & work", _DRIVABLE),
    PlaceLabel.OPEN_AREA: LabelSemantics("drivable & storage access", _DRIVABLE | {PlaceLabel.STORAGE}),
    PlaceLabel.UNIDENTIFIED: LabelSemantics("-", frozenset()),
    PlaceLabel.NONE: LabelSemantics("-", frozenset()),
}
"""Each label's functionality and the labels it connects to."""

LABEL_TABLE_STAGE: Final = "label_table"
"""Stage name of the map-store revisions that record a person's label-table overrides; the grid
decomposition worker re-labels the map from the newest one."""
LABEL_OVERRIDES_KEY: Final = "label_overrides"
"""Summary key of those revisions: {category as a decimal string: label name}."""

_ALIASES: Final = {"PALLET_CELL": "STORAGE", "PALLET_CELLS": "STORAGE", "OPEN": "OPEN_AREA",
                   "UNKNOWN": "UNIDENTIFIED"}


def parse_place_label(name: str) -> PlaceLabel:
    """A :class:`PlaceLabel` from its name (``corridor``, ``junction``, ``storage``, ``pallet_cell``...).

    Raises
    ------
    PlaceLabelError
        A name that is not a place label or one of its aliases.
    """
    key = name.strip().upper().replace(" ", "_").replace("-", "_")
    key = _ALIASES.get(key, key)
    try:
        return PlaceLabel[key]
    except KeyError as err:
        names = ", ".join(label.name.lower() for label in PlaceLabel)
        raise PlaceLabelError(f"unknown place label {name!r}; use one of {names}") from err


def parse_label_table(raw: Mapping[str, str]) -> dict[int, PlaceLabel]:
    """``{"0": "corridor", "3": "pallet cell"}`` (category -> label name, as stored) -> {0: CORRIDOR, 3: STORAGE}.

    Raises
    ------
    PlaceLabelError
        A category that is not a non-negative integer, or a label that is not a place label (``none`` is
        not one a person can choose).
    """
    out: dict[int, PlaceLabel] = {}
    for key, value in raw.items():
        if not (isinstance(key, str) and key.isdigit() and len(key) <= 6):
            raise PlaceLabelError(f"category {key!r} must be a non-negative integer, e.g. '3'")
        label = parse_place_label(str(value))
        if label is PlaceLabel.NONE:
            raise PlaceLabelError(f"category {key}: 'none' marks occupied or unknown cells, not a place")
        out[int(key)] = label
    return out


__all__ = [
    "LABEL_OVERRIDES_KEY",
    "LABEL_TABLE",
    "LABEL_TABLE_STAGE",
    "LabelSemantics",
    "PlaceLabelError",
    "parse_label_table",
    "parse_place_label",
]
