"""Seed a semantic grid from stored label and entropy layers, so a restarted worker keeps its map.

The store holds only the inferred layers, not the per-cell distributions nor the pose graphs. Each
labelled static cell comes back as pseudo-evidence for its label: the log-evidence ``w`` whose
one-hot distribution (``w`` on the label, 0 elsewhere) has the stored normalised entropy, capped at
``max_log_evidence`` so that fresh observations can still overturn it, spread over ``hits``
observations so the cell passes inference's ``min_hits``. Seeded cells belong to no keyframe: they
stay where the last revision put them when later loop closures move the trajectory. Their height is
unknown and taken as 0 m, which keeps them out of taller neighbours' band resolution until fresh
observations raise their mean height.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from services.semantic_fusion.classes import DYNAMIC_CLASSES, N_CLASSES
from services.semantic_fusion.errors import SemanticFusionError
from services.semantic_fusion.grid import SemanticGrid
from shared.store import StoredLayer
from shared.vocabulary import SemanticClass

_TABLE_STEPS = 4001


def _one_hot_entropy(log_evidence: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    """Normalised entropy of the softmax of ``w`` on one of K columns and 0 on the others."""
    p = 1.0 / (1.0 + (N_CLASSES - 1) * np.exp(-log_evidence))
    q = (1.0 - p) / (N_CLASSES - 1)
    return np.asarray(-(p * np.log(p) + (N_CLASSES - 1) * q * np.log(q)) / math.log(N_CLASSES))


def evidence_for_entropy(entropy: npt.ArrayLike, *, max_log_evidence: float) -> npt.NDArray[np.float64]:
    """Log-evidence (n,) >= 0 that gives a one-hot cell the normalised ``entropy`` (n,) in [0, 1].

    Entropies below what ``max_log_evidence`` gives, and non-finite ones, map to ``max_log_evidence``.

    Examples
    --------
    >>> evidence_for_entropy([1.0], max_log_evidence=8.0).round(6).tolist()
    [0.0]
    """
    h = np.asarray(entropy, dtype=np.float64).reshape(-1)
    w = np.linspace(0.0, max_log_evidence, _TABLE_STEPS)
    table = _one_hot_entropy(w)  # decreasing in w
    out = np.interp(np.clip(h, 0.0, 1.0), table[::-1], w[::-1])
    out[~np.isfinite(h)] = max_log_evidence
    return np.asarray(out)


def seed_grid(
    grid: SemanticGrid,
    labels: npt.ArrayLike,
    entropy: npt.ArrayLike,
    *,
    origin_x_m: float,
    origin_y_m: float,
    hits: int = 2,
    max_log_evidence: float = 8.0,
) -> int:
    """Add a stored label layer to ``grid`` as pseudo-evidence; return the number of cells seeded.

    Parameters
    ----------
    grid : SemanticGrid
        The grid to seed, at the layers' resolution.
    labels : (H, W) array_like of uint8
        :class:`SemanticClass` codes, GridLayer order (row 0 = lowest y).
    entropy : (H, W) array_like of float
        Normalised entropy per cell, as stored beside ``labels``.
    origin_x_m, origin_y_m : float
        Lower-left corner of cell (0, 0), metres.
    hits : int
        Observations each seeded cell counts as.
    max_log_evidence : float
        Largest log-evidence a seeded cell gets (about two confident observations at 8).

    Raises
    ------
    SemanticFusionError
        Shapes differ, codes outside :class:`SemanticClass`, ``hits < 1`` or ``max_log_evidence <= 0``.
    """
    codes = np.asarray(labels)
    h = np.asarray(entropy, dtype=np.float64)
    if codes.ndim != 2 or codes.shape != h.shape:
        raise SemanticFusionError(f"labels {codes.shape} and entropy {h.shape} must be equal 2-D shapes")
    if codes.size and (codes.min() < 0 or codes.max() > max(SemanticClass)):
        raise SemanticFusionError(f"label codes must be in 0..{int(max(SemanticClass))}")
    if hits < 1 or not max_log_evidence > 0:
        raise SemanticFusionError(f"need hits >= 1 and max_log_evidence > 0, got {hits}, {max_log_evidence}")
    skipped = [int(SemanticClass.NONE), *(int(c) for c in DYNAMIC_CLASSES)]
    rows, cols = np.nonzero(~np.isin(codes, skipped))
    if not rows.size:
        return 0
    res = grid.resolution_m
    centres = np.stack([origin_x_m + (cols + 0.5) * res, origin_y_m + (rows + 0.5) * res], axis=1)
    cell_rows = grid.rows_of(centres)
    columns = codes[rows, cols].astype(np.intp) - 1  # distribution column k is class k + 1
    weights = evidence_for_entropy(h[rows, cols], max_log_evidence=max_log_evidence) / hits
    n = rows.size
    grid.accumulate(np.tile(cell_rows, hits), np.tile(columns, hits),
                    np.tile(weights, hits), np.zeros(n * hits), np.zeros(n * hits))
    return int(n)


def seed_from_stored(grid: SemanticGrid, labels: StoredLayer | None, entropy: StoredLayer | None) -> int:
    """Seed ``grid`` (:func:`seed_grid`) from the stored label and entropy layers; the cells seeded (0 with none).

    Raises
    ------
    SemanticFusionError
        When the two layers are of different revisions or shapes, or of another resolution than ``grid``.
    """
    if labels is None or entropy is None:
        return 0
    lab, ent = labels.layer, entropy.layer
    if (labels.revision_id != entropy.revision_id or lab.data.shape != ent.data.shape
            or abs(lab.resolution_m - grid.resolution_m) > 1e-9):
        raise SemanticFusionError(f"stored semantic layers (revisions {labels.revision_id}, {entropy.revision_id}; "
                                  f"{lab.resolution_m} m) do not fit this grid ({grid.resolution_m} m)")
    return seed_grid(grid, lab.data, ent.data, origin_x_m=lab.origin_x_m, origin_y_m=lab.origin_y_m)
