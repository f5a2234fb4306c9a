"""Accuracy measures: trajectory error and label agreement with a ground-truth raster."""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
import numpy.typing as npt

from services.semantic_fusion.errors import SemanticFusionError
from services.semantic_fusion.inference import SemanticLayers
from shared.vocabulary import SemanticClass


class LabelAccuracy(NamedTuple):
    """``correct`` / ``cells``: labelled cells agreeing with the truth among those non-empty in both;
    ``spurious``: labelled cells the truth says are empty."""

    correct: int
    cells: int
    spurious: int

    @property
    def fraction(self) -> float:
        """Share of correct labels, NaN with no cells."""
        return self.correct / self.cells if self.cells else math.nan


def absolute_trajectory_error(estimated: npt.ArrayLike, truth: npt.ArrayLike) -> float:
    """RMS position error (metres) between (n, 3) pose sequences in the same anchored frame."""
    e, t = np.asarray(estimated, dtype=np.float64), np.asarray(truth, dtype=np.float64)
    if e.shape != t.shape or e.ndim != 2 or e.shape[1] != 3 or e.shape[0] == 0:
        raise SemanticFusionError(f"need two equal (n, 3) pose arrays, got {e.shape} and {t.shape}")
    return float(np.sqrt(np.mean(np.sum((e[:, :2] - t[:, :2]) ** 2, axis=1))))


def label_accuracy(layers: SemanticLayers, truth: npt.NDArray[np.uint8], *, truth_origin_x_m: float = 0.0,
                   truth_origin_y_m: float = 0.0, exclude: frozenset[SemanticClass] = frozenset()) -> LabelAccuracy:
    """Compare a label layer with a truth raster of the same resolution on a shared cell lattice.

    Cells labelled with a class in ``exclude`` (e.g. the dynamic classes, absent from a static
    truth) are left out.
    """
    res = layers.resolution_m
    dc = round((layers.origin_x_m - truth_origin_x_m) / res)
    dr = round((layers.origin_y_m - truth_origin_y_m) / res)
    rows, cols = np.nonzero(layers.labels != SemanticClass.NONE)
    got = layers.labels[rows, cols]
    tr, tc = rows + dr, cols + dc
    inside = (tr >= 0) & (tr < truth.shape[0]) & (tc >= 0) & (tc < truth.shape[1])
    want = np.zeros(got.size, dtype=np.uint8)
    want[inside] = truth[tr[inside], tc[inside]]
    keep = ~np.isin(got, [int(c) for c in exclude])
    both = keep & (want != SemanticClass.NONE)
    return LabelAccuracy(int(np.sum(both & (got == want))), int(both.sum()),
                         int(np.sum(keep & (want == SemanticClass.NONE))))
