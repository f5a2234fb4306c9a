"""Metric-topological templates on the adjacency graph (paper B, Algorithm 1): junctions, corridors."""

from __future__ import annotations

import enum
import itertools

import networkx as nx


class Template(enum.Enum):
    """Which template a node of the adjacency graph matches."""

    X_JUNCTION = "x_junction"
    T_JUNCTION = "t_junction"
    CORRIDOR = "corridor"
    DEAD_END = "dead_end"
    NONE = "none"


def match_templates(graph: nx.Graph) -> dict[int, Template]:
    """Match every node of a connectivity graph (valid links only) against the templates.

    A node with three (four) neighbours is a T (X) junction when no two of its neighbours share
    a neighbour other than itself (Algorithm 1: the branches only meet here). A node with two
    such neighbours is a corridor piece, with one a dead end; anything else matches nothing.

    Parameters
    ----------
    graph : networkx.Graph
        Nodes are faces, edges their connected links.

    Returns
    -------
    dict
        Template per node.
    """
    out: dict[int, Template] = {}
    for node in graph.nodes:
        nbrs = list(graph.neighbors(node))
        valid = all(
            set(graph.neighbors(a)) & set(graph.neighbors(b)) <= {node} and not graph.has_edge(a, b)
            for a, b in itertools.combinations(nbrs, 2)
        )
        if not valid:
            out[node] = Template.NONE
        elif len(nbrs) == 4:
            out[node] = Template.X_JUNCTION
        elif len(nbrs) == 3:
            out[node] = Template.T_JUNCTION
        elif len(nbrs) == 2:
            out[node] = Template.CORRIDOR
        elif len(nbrs) == 1:
            out[node] = Template.DEAD_END
        else:
            out[node] = Template.NONE
    return out
