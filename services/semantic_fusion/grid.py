"""A sparse semantic grid: per observed cell, accumulated class evidence, hits and height.

Bayes with the end-point model: an observation labelled ``l`` with confidence ``c`` is modelled as
``p(z = l | m = l) = c`` and ``p(z = l | m = k) = (1 - c) / (K - 1)`` for ``k != l``. In log space
the update adds ``log p(z | m = k)`` to every class; dropping the part common to all classes (it
cancels in the normalising factor) leaves one addition, ``log(c (K - 1) / (1 - c))`` to column
``l``. A cell therefore stores unnormalised log-probabilities starting at 0 (uniform), the
normalising factor is applied when a distribution is read, and every update is a plain sum: an
observation can be taken out again exactly, which is what re-projection after a loop closure does.

Dynamic classes (forklift, human) decay: their evidence, hits and heights are stored scaled by
``exp((t - t_ref) / tau)`` and read scaled by ``exp(-(now - t_ref) / tau)``, so an observation at
time ``t`` weighs ``exp(-(now - t) / tau)`` while sums stay linear. ``t_ref`` is moved forward
(rescaling the stored columns once) before the scale could overflow float32.

Storage is a :class:`CellIndex` from cell key to a row of one dense float32 array that doubles as it
fills; only cells that were ever hit have a row.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
import numpy.typing as npt

from services.semantic_fusion.cell_index import CellIndex
from services.semantic_fusion.classes import N_CLASSES, dynamic_columns
from services.semantic_fusion.errors import SemanticFusionError

_OFFSET = 1 << 30
_STRIDE = 1 << 31
_MAX_EXPONENT = 30.0
_HITS, _DYN_HITS, _HEIGHT, _DYN_HEIGHT = N_CLASSES, N_CLASSES + 1, N_CLASSES + 2, N_CLASSES + 3
_WIDTH = N_CLASSES + 4


class GridCells(NamedTuple):
    """The observed cells of a :class:`SemanticGrid` at one instant.

    Attributes
    ----------
    rows_cols : (m, 2) int64
        World cell indices (row = floor(y / resolution), col = floor(x / resolution)).
    log_evidence : (m, K) float32
        Unnormalised log-probability per class (0 = uniform), dynamic classes decayed to ``now``.
    hits : (m,) float32
        Number of observations, dynamic ones decayed.
    heights : (m,) float32
        Mean observed height, metres.
    """

    rows_cols: npt.NDArray[np.int64]
    log_evidence: npt.NDArray[np.float32]
    hits: npt.NDArray[np.float32]
    heights: npt.NDArray[np.float32]


def evidence_weights(confidences: npt.ArrayLike, *, max_confidence: float = 0.9) -> npt.NDArray[np.float32]:
    """Log-evidence each observation adds to its label's column, (n,) float32 >= 0.

    ``log(c (K - 1) / (1 - c))`` with ``c`` clipped to ``[1 / K, max_confidence]``: a confidence at
    or below chance adds nothing, and no single observation can settle a cell on its own.

    Examples
    --------
    >>> float(evidence_weights([1.0 / 7.0])[0])
    0.0
    """
    if not 1.0 / N_CLASSES < max_confidence < 1.0:
        raise SemanticFusionError(f"max_confidence must be in (1/{N_CLASSES}, 1), got {max_confidence}")
    c = np.clip(np.asarray(confidences, dtype=np.float64), 1.0 / N_CLASSES, max_confidence)
    return np.log(c * (N_CLASSES - 1) / (1.0 - c)).astype(np.float32)


def cell_indices(points_xy: npt.ArrayLike, *, resolution_m: float) -> npt.NDArray[np.int64]:
    """World cell (row, col) of each point, (n, 2) int64: row = floor(y / res), col = floor(x / res)."""
    pts = np.asarray(points_xy, dtype=np.float64).reshape(-1, 2)
    return np.floor(pts[:, ::-1] / resolution_m).astype(np.int64)


class SemanticGrid:
    """Sparse grid of per-cell class evidence in the map frame.

    Parameters
    ----------
    resolution_m : float
        Cell edge, metres.
    dynamic_half_life_s : float
        Time after which a dynamic-class observation weighs half, seconds.
    initial_cells : int
        Rows allocated up front; storage doubles when full.
    """

    def __init__(self, *, resolution_m: float = 0.05, dynamic_half_life_s: float = 20.0,
                 initial_cells: int = 4096) -> None:
        if not (math.isfinite(resolution_m) and resolution_m > 0):
            raise SemanticFusionError(f"resolution_m must be positive, got {resolution_m}")
        if not (math.isfinite(dynamic_half_life_s) and dynamic_half_life_s > 0):
            raise SemanticFusionError(f"dynamic_half_life_s must be positive, got {dynamic_half_life_s}")
        self._resolution = float(resolution_m)
        self._tau_s = dynamic_half_life_s / math.log(2.0)
        self._t_ref_s: float | None = None
        self._index = CellIndex()
        self._values = np.zeros((max(16, initial_cells), _WIDTH), dtype=np.float32)
        self._keys = np.zeros(self._values.shape[0], dtype=np.int64)
        self._dynamic = np.zeros(N_CLASSES, dtype=bool)
        self._dynamic[dynamic_columns()] = True
        self._dynamic_value_columns = np.append(dynamic_columns(), [_DYN_HITS, _DYN_HEIGHT])

    @property
    def resolution_m(self) -> float:
        """Cell edge, metres."""
        return self._resolution

    @property
    def n_cells(self) -> int:
        """Cells that have a row (were hit at least once)."""
        return len(self._index)

    @property
    def nbytes(self) -> int:
        """Approximate memory held, bytes (arrays plus the key dict)."""
        return int(self._values.nbytes + self._keys.nbytes + self._index.nbytes)

    def rows_of(self, points_xy: npt.ArrayLike) -> npt.NDArray[np.int64]:
        """Storage row of the cell of each map point (n, 2), creating rows for new cells."""
        rc = cell_indices(points_xy, resolution_m=self._resolution)
        keys = (rc[:, 0] + _OFFSET) * _STRIDE + (rc[:, 1] + _OFFSET)
        unique, inverse = np.unique(keys, return_inverse=True)
        before = len(self._index)
        rows = self._index.rows(unique)
        if len(self._index) > before:
            self._reserve(len(self._index))
            new = rows >= before
            self._keys[rows[new]] = unique[new]
        return np.asarray(rows[inverse.reshape(-1)], dtype=np.int64)

    def _reserve(self, n_rows: int) -> None:
        capacity = self._values.shape[0]
        if n_rows <= capacity:
            return
        while capacity < n_rows:
            capacity *= 2
        grown = np.zeros((capacity, _WIDTH), dtype=np.float32)
        grown[: self._values.shape[0]] = self._values
        keys = np.zeros(capacity, dtype=np.int64)
        keys[: self._keys.size] = self._keys
        self._values, self._keys = grown, keys

    def _scales(self, columns: npt.NDArray[np.intp], stamps_s: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        dynamic = self._dynamic[columns]
        scale = np.ones(columns.size)
        if not dynamic.any():
            return scale
        newest = float(stamps_s[dynamic].max())
        if self._t_ref_s is None:
            self._t_ref_s = newest
        elif (newest - self._t_ref_s) / self._tau_s > _MAX_EXPONENT:
            factor = math.exp(-(newest - self._t_ref_s) / self._tau_s)
            self._values[: self.n_cells, self._dynamic_value_columns] *= np.float32(factor)
            self._t_ref_s = newest
        scale[dynamic] = np.exp((stamps_s[dynamic] - self._t_ref_s) / self._tau_s)
        return scale

    def accumulate(self, rows: npt.ArrayLike, columns: npt.ArrayLike, weights: npt.ArrayLike,
                   heights_m: npt.ArrayLike, stamps_s: npt.ArrayLike, *, sign: float = 1.0) -> None:
        """Add (``sign`` 1) or take out (``sign`` -1) observations of rows from :meth:`rows_of`.

        Parameters
        ----------
        rows : (n,) int
            Storage rows.
        columns : (n,) int
            Distribution column of each observation's label.
        weights : (n,) float
            Log-evidence per observation (see :func:`evidence_weights`).
        heights_m : (n,) float
            Observed heights, metres.
        stamps_s : (n,) float
            Observation times, seconds (any fixed epoch).
        """
        r = np.asarray(rows, dtype=np.int64).reshape(-1)
        col = np.asarray(columns, dtype=np.intp).reshape(-1)
        w = np.asarray(weights, dtype=np.float64).reshape(-1)
        h = np.asarray(heights_m, dtype=np.float64).reshape(-1)
        t = np.asarray(stamps_s, dtype=np.float64).reshape(-1)
        if not r.size == col.size == w.size == h.size == t.size:
            raise SemanticFusionError(
                f"rows, columns, weights, heights and stamps differ in length: {r.size}, {col.size}, "
                f"{w.size}, {h.size}, {t.size}")
        if r.size == 0:
            return
        if r.min() < 0 or r.max() >= self.n_cells or col.min() < 0 or col.max() >= N_CLASSES:
            raise SemanticFusionError("rows or columns out of range")
        scale = sign * self._scales(col, t)
        dynamic = self._dynamic[col]
        hit_col = np.where(dynamic, _DYN_HITS, _HITS)
        height_col = np.where(dynamic, _DYN_HEIGHT, _HEIGHT)
        flat = np.concatenate([r * _WIDTH + col, r * _WIDTH + hit_col, r * _WIDTH + height_col])
        np.add.at(self._values.reshape(-1), flat, np.concatenate([w * scale, scale, h * scale]).astype(np.float32))

    def cells(self, *, now_s: float) -> GridCells:
        """Every cell with a row, dynamic evidence decayed to ``now_s`` (seconds, same epoch as stamps)."""
        n = self.n_cells
        values = self._values[:n]
        decay = 1.0 if self._t_ref_s is None else math.exp(-(now_s - self._t_ref_s) / self._tau_s)
        evidence = values[:, :N_CLASSES].copy()
        evidence[:, self._dynamic] *= np.float32(decay)
        np.maximum(evidence, 0.0, out=evidence)  # rounding after take-outs must not favour other classes
        hits = values[:, _HITS] + np.float32(decay) * values[:, _DYN_HITS]
        height_sum = values[:, _HEIGHT] + np.float32(decay) * values[:, _DYN_HEIGHT]
        heights = np.divide(height_sum, hits, out=np.zeros_like(hits), where=hits > 1e-6)
        keys = self._keys[:n]
        rows_cols = np.stack([keys // _STRIDE - _OFFSET, keys % _STRIDE - _OFFSET], axis=1)
        return GridCells(rows_cols, evidence, hits.astype(np.float32), heights.astype(np.float32))
