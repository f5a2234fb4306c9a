"""Label table, templates and links."""

from __future__ import annotations

import networkx as nx
import pytest

from services.grid_decomposition import (
    Connection,
    DecompositionError,
    Template,
    link_connection,
    match_templates,
    parse_label,
)
from shared.vocabulary import PlaceLabel


def test_match_templates_marks_cross_and_tee_but_not_a_grid_of_cells() -> None:
    g = nx.Graph([(0, 1), (0, 2), (0, 3), (0, 4), (1, 5), (5, 6)])
    t = match_templates(g)
    assert t[0] is Template.X_JUNCTION
    assert t[1] is Template.CORRIDOR and t[6] is Template.DEAD_END
    g.remove_node(4)
    assert match_templates(g)[0] is Template.T_JUNCTION
    grid = nx.grid_2d_graph(3, 3)
    assert all(v is not Template.X_JUNCTION for v in match_templates(grid).values())


def test_link_connection_follows_the_connectability_table() -> None:
    assert (link_connection(PlaceLabel.CORRIDOR, PlaceLabel.STORAGE, cogent=False, door=False)
            is Connection.STORAGE_ACCESS)
    assert link_connection(PlaceLabel.JUNCTION, PlaceLabel.STORAGE, cogent=False, door=False) is Connection.DISCONNECTED
    assert (link_connection(PlaceLabel.UNIDENTIFIED, PlaceLabel.CORRIDOR, cogent=False, door=False)
            is Connection.DISCONNECTED)
    assert link_connection(PlaceLabel.ROOM, PlaceLabel.CORRIDOR, cogent=True, door=True) is Connection.DOOR
    assert link_connection(PlaceLabel.ROOM, PlaceLabel.CORRIDOR, cogent=True, door=False) is Connection.DISCONNECTED
    assert link_connection(PlaceLabel.JUNCTION, PlaceLabel.CORRIDOR, cogent=False, door=False) is Connection.CONNECTED


def test_parse_label_accepts_aliases_and_rejects_nonsense() -> None:
    assert parse_label("pallet cell") is PlaceLabel.STORAGE
    assert parse_label("Open-Area") is PlaceLabel.OPEN_AREA
    with pytest.raises(DecompositionError, match="unknown place label 'shelf'"):
        parse_label("shelf")
