"""Place labels as people write them, and the label table's connect-ability."""

from __future__ import annotations

import pytest

from shared.places import Connection, PlaceLabelError, link_connection, parse_label, parse_label_table
from shared.vocabulary import PlaceLabel


@pytest.mark.parametrize(("name", "label"), [
    ("corridor", PlaceLabel.CORRIDOR), ("Pallet cell", PlaceLabel.STORAGE), ("open-area", PlaceLabel.OPEN_AREA),
    ("unknown", PlaceLabel.UNIDENTIFIED)])
def test_parse_label_takes_names_and_aliases(name: str, label: PlaceLabel) -> None:
    assert parse_label(name) is label


@pytest.mark.parametrize(("raw", "message"), [
    ({"3": "shelf"}, "unknown place label 'shelf'"), ({"-1": "corridor"}, "non-negative integer"),
    ({"2": "none"}, "not a place")])
def test_parse_label_table_refuses_what_is_not_a_choice(raw: dict[str, str], message: str) -> None:
    with pytest.raises(PlaceLabelError, match=message):
        parse_label_table(raw)


def test_storage_opens_only_onto_drivable_places_that_give_access() -> None:
    assert link_connection(PlaceLabel.CORRIDOR, PlaceLabel.STORAGE, cogent=False, door=False) \
        is Connection.STORAGE_ACCESS
    assert link_connection(PlaceLabel.JUNCTION, PlaceLabel.STORAGE, cogent=False, door=False) \
        is Connection.DISCONNECTED
    assert link_connection(PlaceLabel.ROOM, PlaceLabel.CORRIDOR, cogent=True, door=True) is Connection.DOOR
