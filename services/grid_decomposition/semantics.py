"""Human semantics (paper C, Table II) at work: how two labelled places are linked, and label names parsed.

The labels are :class:`shared.vocabulary.PlaceLabel` (their values are the codes of ``labels.png``); what each
means and connects to is :data:`shared.places.LABEL_TABLE`.
"""

from __future__ import annotations

import enum
from collections.abc import Mapping

from services.grid_decomposition.errors import DecompositionError
from shared import places
from shared.places import LABEL_TABLE, PlaceLabelError, parse_place_label
from shared.vocabulary import PlaceLabel


class Connection(enum.Enum):
    """Attribute of a link between two regions (dual of an edge's cogency)."""

    CONNECTED = "connected"
    STORAGE_ACCESS = "storage_access"
    DOOR = "door"
    DISCONNECTED = "disconnected"


def parse_label(name: str) -> PlaceLabel:
    """A :class:`PlaceLabel` from its name (``corridor``, ``storage``, ``pallet_cell``...); see
    :func:`shared.places.parse_place_label`.

    Raises
    ------
    DecompositionError
        A name that is not a place label.
    """
    try:
        return parse_place_label(name)
    except PlaceLabelError as err:
        raise DecompositionError(str(err)) from err


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


def parse_label_table(raw: Mapping[str, str]) -> dict[int, PlaceLabel]:
    """Category -> label overrides as a person stored them; see :func:`shared.places.parse_label_table`.

    Raises
    ------
    DecompositionError
        A category that is not a non-negative integer, or a label that is not a place label.
    """
    try:
        return places.parse_label_table(raw)
    except PlaceLabelError as err:
        raise DecompositionError(str(err)) from err
