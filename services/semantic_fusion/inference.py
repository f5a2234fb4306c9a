"""Final labels from per-cell class evidence: entropy bands and same-surface neighbours.

A cell's normalised Shannon entropy ``H = -sum p log p / log K`` (0 = certain, 1 = uniform) sorts it
into one of three bands:

* ``H < confident_entropy``: the arg-max label is taken as it is, never mixed with neighbours, so
  thin objects (a rack upright one or two cells wide) survive next to large surfaces;
* ``H >= unconfident_entropy``: the cell is labelled ``UNKNOWN``;
* in between: the cell's distribution is combined with those of adjacent cells on the same
  physical surface -- within ``neighbour_radius_cells``, non-empty, linked to the cell through
  non-empty cells, with a mean height within ``max_height_difference_m`` and not unconfident
  themselves -- each weighted by its confidence ``1 - H``, and the arg-max of the sum is taken.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
import numpy.typing as npt

from services.semantic_fusion.classes import CLASS_COLOURS, DISTRIBUTION_CLASSES, N_CLASSES
from services.semantic_fusion.errors import SemanticFusionError
from services.semantic_fusion.grid import GridCells
from shared.store.records import GridLayer
from shared.vocabulary import LayerName, SemanticClass

NO_ENTROPY = -1.0
"""Entropy-layer value of cells with no evidence."""
LABEL_ENCODING = "semantic_labels"
"""``meta["encoding"]`` of label layers: uint8 codes, ``meta["classes"][code]`` names each."""
ENTROPY_ENCODING = "normalised_entropy"
"""``meta["encoding"]`` of entropy layers: float32 in [0, 1], :data:`NO_ENTROPY` where there is no data."""

_CODES = np.array([int(c) for c in DISTRIBUTION_CLASSES], dtype=np.uint8)


class CellLabels(NamedTuple):
    """Per-cell inference result, aligned with :attr:`GridCells.rows_cols`.

    ``labels`` (m,) uint8 :class:`SemanticClass` codes (``NONE`` where the cell has too few hits),
    ``entropy`` (m,) float32 normalised entropy in [0, 1], ``raw_labels`` (m,) uint8 plain arg-max.
    """

    labels: npt.NDArray[np.uint8]
    entropy: npt.NDArray[np.float32]
    raw_labels: npt.NDArray[np.uint8]


class SemanticLayers(NamedTuple):
    """Dense label and entropy rasters, ``[row, col]`` with row 0 at the lowest y (GridLayer order).

    ``labels`` (H, W) uint8 :class:`SemanticClass` codes, ``entropy`` (H, W) float32 in [0, 1] and
    :data:`NO_ENTROPY` where there is no evidence; ``origin_*_m`` is the lower-left corner of cell (0, 0).
    """

    labels: npt.NDArray[np.uint8]
    entropy: npt.NDArray[np.float32]
    resolution_m: float
    origin_x_m: float
    origin_y_m: float

    def grid_layers(self, *, label_name: str = LayerName.SEMANTIC_LABEL,
                    entropy_name: str = LayerName.SEMANTIC_ENTROPY) -> tuple[GridLayer, GridLayer]:
        """The two rasters as store layers, each described by its meta.

        The label layer's meta is ``{"encoding": "semantic_labels", "classes": [name of code 0, 1,
        ...], "colours": [[r, g, b] of code 0, 1, ...]}``, enough for a reader (the API's PNG) to
        draw it without knowing :class:`SemanticClass`; the entropy layer's is
        ``{"encoding": "normalised_entropy", "no_data": NO_ENTROPY}``.
        """
        return (
            GridLayer(label_name, self.labels, self.resolution_m, self.origin_x_m, self.origin_y_m,
                      {"encoding": LABEL_ENCODING, "classes": [c.name.lower() for c in SemanticClass],
                       "colours": [list(CLASS_COLOURS[c]) for c in SemanticClass]}),
            GridLayer(entropy_name, self.entropy, self.resolution_m, self.origin_x_m, self.origin_y_m,
                      {"encoding": ENTROPY_ENCODING, "no_data": NO_ENTROPY}),
        )


def normalised_entropy(log_evidence: npt.ArrayLike) -> npt.NDArray[np.float32]:
    """Shannon entropy of the softmax of each row of ``log_evidence`` (m, K), divided by log K.

    Examples
    --------
    >>> normalised_entropy(np.zeros((1, 4))).round(6).tolist()
    [1.0]
    """
    e = np.asarray(log_evidence, dtype=np.float64)
    if e.ndim != 2 or e.shape[1] < 2:
        raise SemanticFusionError(f"log_evidence must be (m, K >= 2), got shape {e.shape}")
    z = e - e.max(axis=1, keepdims=True)
    p = np.exp(z)
    total = p.sum(axis=1, keepdims=True)
    p /= total
    log_p = z - np.log(total)
    return np.asarray(-(p * log_p).sum(axis=1) / math.log(e.shape[1]), dtype=np.float32)


def _probabilities(log_evidence: npt.NDArray[np.float32]) -> npt.NDArray[np.float64]:
    z = log_evidence.astype(np.float64) - log_evidence.max(axis=1, keepdims=True)
    p = np.exp(z)
    return np.asarray(p / p.sum(axis=1, keepdims=True))


def infer_labels(
    cells: GridCells,
    *,
    min_hits: float = 2.0,
    confident_entropy: float = 0.45,
    unconfident_entropy: float = 0.9,
    neighbour_radius_cells: int = 2,
    max_height_difference_m: float = 0.5,
) -> CellLabels:
    """Label every cell of ``cells`` (see the module docstring for the bands).

    Parameters
    ----------
    cells : GridCells
        Observed cells and their evidence.
    min_hits : float
        Cells with fewer (decayed) observations are empty: ``NONE``. Filters one-off false positives.
    confident_entropy, unconfident_entropy : float
        Band limits on the normalised entropy, ``0 <= confident < unconfident <= 1``.
    neighbour_radius_cells : int
        Chebyshev radius of the neighbourhood searched for band cells, cells.
    max_height_difference_m : float
        Largest mean-height difference between cells of one surface, metres.
    """
    if not 0.0 <= confident_entropy < unconfident_entropy <= 1.0:
        raise SemanticFusionError(
            f"need 0 <= confident_entropy < unconfident_entropy <= 1, got {confident_entropy}, "
            f"{unconfident_entropy}")
    if neighbour_radius_cells < 0 or max_height_difference_m < 0 or min_hits < 0:
        raise SemanticFusionError("neighbour_radius_cells, max_height_difference_m and min_hits must be >= 0")
    m = cells.hits.size
    if cells.log_evidence.shape != (m, N_CLASSES) or cells.rows_cols.shape != (m, 2):
        raise SemanticFusionError(f"inconsistent cells: {cells.rows_cols.shape}, {cells.log_evidence.shape}")
    entropy = normalised_entropy(cells.log_evidence) if m else np.empty(0, dtype=np.float32)
    raw = _CODES[np.argmax(cells.log_evidence, axis=1)] if m else np.empty(0, dtype=np.uint8)
    occupied = cells.hits >= min_hits
    labels = np.where(occupied, raw, np.uint8(SemanticClass.NONE)).astype(np.uint8)
    labels[occupied & (entropy >= unconfident_entropy)] = SemanticClass.UNKNOWN
    band = np.flatnonzero(occupied & (entropy >= confident_entropy) & (entropy < unconfident_entropy))
    if band.size and neighbour_radius_cells > 0:
        labels[band] = _resolve_band(cells, occupied, entropy, band, radius=neighbour_radius_cells,
                                     max_dh=max_height_difference_m, unconfident=unconfident_entropy)
    return CellLabels(labels, entropy, np.where(occupied, raw, np.uint8(SemanticClass.NONE)).astype(np.uint8))


def _resolve_band(cells: GridCells, occupied: npt.NDArray[np.bool_], entropy: npt.NDArray[np.float32],
                  band: npt.NDArray[np.intp], *, radius: int, max_dh: float,
                  unconfident: float) -> npt.NDArray[np.uint8]:
    lo = cells.rows_cols.min(axis=0) - radius
    shape = tuple(int(v) for v in cells.rows_cols.max(axis=0) - lo + radius + 1)
    index = np.full(shape, -1, dtype=np.int64)
    local = cells.rows_cols - lo
    kept = np.flatnonzero(occupied)
    index[local[kept, 0], local[kept, 1]] = kept
    prob = _probabilities(cells.log_evidence)
    score = prob[band].copy()
    rr, cc = local[band, 0], local[band, 1]
    for dr in range(-radius, radius + 1):
        for dc in range(-radius, radius + 1):
            if dr == 0 and dc == 0:
                continue
            nb = index[rr + dr, cc + dc]
            ok = nb >= 0
            half = (int(dr / 2), int(dc / 2))  # link cell towards the centre: same surface, not a gap
            if half != (0, 0):
                ok &= index[rr + half[0], cc + half[1]] >= 0
            nb_safe = np.where(ok, nb, 0)
            ok &= np.abs(cells.heights[nb_safe] - cells.heights[band]) <= max_dh
            ok &= entropy[nb_safe] < unconfident
            weight = np.where(ok, 1.0 - entropy[nb_safe], 0.0)
            score += weight[:, None] * prob[nb_safe]
    return np.asarray(_CODES[np.argmax(score, axis=1)], dtype=np.uint8)


def rasterise(cells: GridCells, result: CellLabels, *, resolution_m: float) -> SemanticLayers:
    """Dense label and entropy layers over the bounding box of the non-empty cells.

    With no non-empty cell the layers are a single ``NONE`` cell at the origin.
    """
    keep = result.labels != SemanticClass.NONE
    if not keep.any():
        return SemanticLayers(np.zeros((1, 1), np.uint8), np.full((1, 1), NO_ENTROPY, np.float32),
                              resolution_m, 0.0, 0.0)
    rc = cells.rows_cols[keep]
    lo = rc.min(axis=0)
    shape = tuple(int(v) for v in rc.max(axis=0) - lo + 1)
    labels = np.zeros(shape, dtype=np.uint8)
    entropy = np.full(shape, NO_ENTROPY, dtype=np.float32)
    local = rc - lo
    labels[local[:, 0], local[:, 1]] = result.labels[keep]
    entropy[local[:, 0], local[:, 1]] = result.entropy[keep]
    return SemanticLayers(labels, entropy, resolution_m, float(lo[1] * resolution_m), float(lo[0] * resolution_m))
