"""Vectorised template matching agrees with Algorithm 1 read literally."""

from __future__ import annotations

import itertools

import networkx as nx
import numpy as np
import pytest

from services.grid_decomposition.templates import template_branches


def _literal(graph: nx.Graph, node: int) -> int:
    nbrs = list(graph.neighbors(node))
    ok = all(
        set(graph.neighbors(a)) & set(graph.neighbors(b)) <= {node} and not graph.has_edge(a, b)
        for a, b in itertools.combinations(nbrs, 2)
    )
    return len(nbrs) if ok else -1


@pytest.mark.parametrize("seed", range(5))
def test_template_branches_agree_with_the_literal_algorithm_on_random_graphs(seed: int) -> None:
    graph = nx.gnm_random_graph(30, 35 + 5 * seed, seed=seed)
    links = np.array(list(graph.edges), dtype=np.int64)
    branches = template_branches(30, links)
    assert branches.tolist() == [_literal(graph, n) for n in range(30)]


def test_template_branches_ignore_duplicate_and_self_links() -> None:
    links = np.array([[0, 1], [1, 0], [0, 2], [0, 3], [3, 3]], dtype=np.int64)
    assert template_branches(4, links).tolist() == [3, 1, 1, 1]
