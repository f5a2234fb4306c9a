"""Gated nearest-neighbour data association of bearings to mapped landmarks."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
from scipy.optimize import linear_sum_assignment

IntArray = npt.NDArray[np.int64]
FloatArray = npt.NDArray[np.float64]

_UNGATED = 1e12


def associate(mahalanobis_sq: FloatArray, *, gate_sq: float) -> tuple[IntArray, npt.NDArray[np.bool_]]:
    """Globally nearest pairing of observations to landmarks, rejecting ambiguous observations.

    Parameters
    ----------
    mahalanobis_sq : ndarray of float64, shape (K, N)
        Squared Mahalanobis distance of observation k's innovation for landmark n.
    gate_sq : float
        Chi-square gate (1 degree of freedom for a bearing).

    Returns
    -------
    matches : ndarray of int64, shape (K,)
        Landmark index per observation, -1 when unmatched.
    ambiguous : ndarray of bool, shape (K,)
        Observations inside the gate of two or more landmarks: neither matched nor fit to
        start a new landmark (an upright behind another one at almost the same bearing).
    """
    k, n = mahalanobis_sq.shape
    matches = np.full(k, -1, dtype=np.int64)
    gated = mahalanobis_sq <= gate_sq
    ambiguous = gated.sum(axis=1) > 1
    if k == 0 or n == 0:
        return matches, ambiguous
    cost = np.where(gated & ~ambiguous[:, None], mahalanobis_sq, _UNGATED)
    rows, cols = linear_sum_assignment(cost)
    ok = cost[rows, cols] < _UNGATED
    matches[rows[ok]] = cols[ok]
    return matches, ambiguous
