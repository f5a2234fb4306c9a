"""Metric-topological templates on the adjacency graph (paper B, Algorithm 1): junctions, corridors."""

from __future__ import annotations

import enum
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt
from scipy import sparse

if TYPE_CHECKING:
    import networkx as nx


class Template(enum.Enum):
    """Which template a node of the adjacency graph matches."""

    X_JUNCTION = "x_junction"
    T_JUNCTION = "t_junction"
    CORRIDOR = "corridor"
    DEAD_END = "dead_end"
    NONE = "none"


_BY_BRANCHES = {4: Template.X_JUNCTION, 3: Template.T_JUNCTION, 2: Template.CORRIDOR, 1: Template.DEAD_END}


def template_branches(n_nodes: int, links: npt.NDArray[np.int64]) -> npt.NDArray[np.int64]:
    """Branch count of every node whose neighbours only meet at it, -1 elsewhere (Algorithm 1, vectorised).

    A node is valid when no two of its neighbours are linked and no two share a neighbour other
    than the node itself. With ``A`` the adjacency matrix and ``d`` the degrees: no triangle
    through ``i`` means ``(A^3)_ii = 0``, and every pair of neighbours having exactly one common
    neighbour means ``(A^4)_ii - (A d)_i = d_i (d_i - 1)`` (the sum of ``(A^2)_ab`` over ordered
    pairs of distinct neighbours, each at least one).

    Parameters
    ----------
    n_nodes : int
        Nodes are 0..n_nodes-1.
    links : (L, 2) int64
        Undirected links; duplicates and self-links are ignored.

    Returns
    -------
    (n_nodes,) int64
        The degree of valid nodes (4 = X junction, 3 = T junction, 2 = corridor, 1 = dead end), -1
        for nodes whose branches meet elsewhere.
    """
    e = np.asarray(links, dtype=np.int64).reshape(-1, 2)
    e = e[e[:, 0] != e[:, 1]]
    rows = np.r_[e[:, 0], e[:, 1]]
    cols = np.r_[e[:, 1], e[:, 0]]
    a = sparse.csr_matrix((np.ones(rows.size), (rows, cols)), shape=(n_nodes, n_nodes))
    a.data[:] = 1.0  # duplicate links were summed
    degree = np.asarray(a.sum(axis=1)).ravel()
    a2 = a @ a
    triangles = np.asarray(a2.multiply(a).sum(axis=1)).ravel()
    four = np.asarray(a2.multiply(a2).sum(axis=1)).ravel() - a @ degree
    valid = (triangles == 0) & (np.rint(four) == degree * (degree - 1))
    return np.where(valid, degree, -1).astype(np.int64)


def match_templates(graph: nx.Graph) -> dict[int, Template]:
    """Match every node of a connectivity graph (valid links only) against the templates.

    A node with three (four) neighbours is a T (X) junction when no two of its neighbours share
    a neighbour other than itself (Algorithm 1: the branches only meet here). A node with two
    such neighbours is a corridor piece, with one a dead end; anything else matches nothing.
    See :func:`template_branches` for the array form.

    Parameters
    ----------
    graph : networkx.Graph
        Nodes are faces, edges their connected links.

    Returns
    -------
    dict
        Template per node.
    """
    nodes = list(graph.nodes)
    index = {node: i for i, node in enumerate(nodes)}
    links = np.array([(index[u], index[v]) for u, v in graph.edges], dtype=np.int64).reshape(-1, 2)
    branches = template_branches(len(nodes), links)
    return {node: _BY_BRANCHES.get(int(b), Template.NONE) for node, b in zip(nodes, branches, strict=True)}
