"""DBSCAN and 1-D peak finding on scipy's light modules, for the rack-row fit.

scikit-learn's ``DBSCAN`` and ``scipy.signal.find_peaks`` are what the fit means (and what the tests compare these
with, label for label and peak for peak), but importing ``sklearn.cluster`` and ``scipy.signal`` takes 0.6 s of
CPU, a third of what ``aisle racks fit`` may take for a whole hall, start-up included. The two functions here
give the same answers from ``scipy.spatial`` and ``scipy.sparse.csgraph``, which the fit loads anyway.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

IntArray = npt.NDArray[np.int64]


def dbscan(points: npt.ArrayLike, *, eps: float, min_samples: int) -> IntArray:
    """Cluster labels of ``points`` (N, D) as ``sklearn.cluster.DBSCAN(eps=eps, min_samples=min_samples)``
    gives them: -1 for noise, clusters numbered in the order of their first core point.

    A core point has at least ``min_samples`` points (itself included) within ``eps`` (Euclidean); core
    points within ``eps`` of each other share a cluster; a border point joins the lowest-numbered cluster of
    the core points within ``eps`` of it (the one scikit-learn's expansion reaches first).
    """
    xy = np.asarray(points, dtype=np.float64)
    count = len(xy)
    labels = np.full(count, -1, dtype=np.int64)
    if count == 0:
        return labels
    pairs = cKDTree(xy).query_pairs(eps, output_type="ndarray").astype(np.int64).reshape(-1, 2)
    core = np.bincount(pairs.ravel(), minlength=count) + 1 >= min_samples
    both = core[pairs[:, 0]] & core[pairs[:, 1]]
    links = pairs[both]
    graph = coo_matrix((np.ones(len(links)), (links[:, 0], links[:, 1])), shape=(count, count))
    _, component = connected_components(graph, directed=False)
    component = np.asarray(component, dtype=np.int64)
    first_core = np.full(int(component.max()) + 1, count, dtype=np.int64)
    np.minimum.at(first_core, component[core], np.flatnonzero(core))
    order = np.argsort(first_core, kind="stable")
    number = np.empty_like(order)
    number[order] = np.arange(len(order))
    labels[core] = number[component[core]]
    one_core = pairs[core[pairs[:, 0]] != core[pairs[:, 1]]]
    if len(one_core):
        inner = np.where(core[one_core[:, 0]], one_core[:, 0], one_core[:, 1])
        border = np.where(core[one_core[:, 0]], one_core[:, 1], one_core[:, 0])
        reached = np.full(count, np.iinfo(np.int64).max, dtype=np.int64)
        np.minimum.at(reached, border, labels[inner])
        touched = reached < np.iinfo(np.int64).max
        labels[touched] = reached[touched]
    return labels


def find_peaks(signal: npt.ArrayLike, *, distance: float = 1.0) -> IntArray:
    """Indices of the peaks of ``signal`` (N,) as ``scipy.signal.find_peaks(signal, distance=distance)`` gives
    them.

    A peak is a sample (or the middle of a flat run, rounded down) higher than both neighbours, never the first
    or last sample; of peaks closer than ``distance`` samples, the higher is kept (scipy's order among equals).
    """
    x = np.asarray(signal, dtype=np.float64).ravel()
    if x.size < 3:
        return np.zeros(0, dtype=np.int64)
    change = np.flatnonzero(x[1:] != x[:-1]) + 1
    starts = np.concatenate([[0], change])
    ends = np.concatenate([change - 1, [x.size - 1]])
    values = x[starts]
    inner = np.arange(1, len(starts) - 1)
    is_peak = (values[inner - 1] < values[inner]) & (values[inner + 1] < values[inner])
    runs = inner[is_peak]
    peaks: IntArray = ((starts[runs] + ends[runs]) // 2).astype(np.int64)
    if distance <= 1 or peaks.size < 2:
        return peaks
    reach = int(np.ceil(distance))
    keep = np.ones(peaks.size, dtype=bool)
    for j in np.argsort(x[peaks])[::-1]:
        if not keep[j]:
            continue
        near = np.abs(peaks - peaks[j]) < reach
        near[j] = False
        keep &= ~near
    kept: IntArray = peaks[keep]
    return kept
