"""The row model shared by segmentation and the join pass: members, line, spacing and phase."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import numpy.typing as npt

from services.pillar_mapping.errors import PillarMappingError
from services.pillar_mapping.frequency import dominant_spacing

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]


class RowModel(NamedTuple):
    """A row being fitted: landmark ``members``, ``centre`` (2,) and unit ``direction`` (2,) of its line,
    spacing ``d`` metres, along-line position ``first`` of its first upright from the centre, ``n``
    uprights, Fourier ``coherence`` and the index of the dominant ``orientation`` it was found along."""

    members: IntArray
    centre: FloatArray
    direction: FloatArray
    d: float
    first: float
    n: int
    coherence: float
    orientation: int


def validated_landmarks(landmarks: npt.ArrayLike) -> FloatArray:
    """The (N, 5) ``x, y, sxx, sxy, syy`` table of ``landmarks`` ((N, 2) gets a 1 cm std); raises on bad input."""
    table = np.asarray(landmarks, dtype=np.float64)
    if table.ndim != 2 or table.shape[1] not in (2, 5):
        raise PillarMappingError(f"landmarks must be an (N, 5) x,y,sxx,sxy,syy table, got shape {table.shape}")
    bad = np.flatnonzero(~np.all(np.isfinite(table), axis=1))
    if bad.size:
        raise PillarMappingError(f"landmarks {bad[:10].tolist()} have non-finite values")
    if table.shape[1] == 2:
        table = np.hstack([table, np.tile([1e-4, 0.0, 1e-4], (len(table), 1))])
    covs = table[:, [2, 3, 3, 4]].reshape(-1, 2, 2)
    if len(table) and np.any(np.linalg.eigvalsh(covs)[:, 0] < -1e-12):
        raise PillarMappingError("landmark covariances must be positive semi-definite")
    return table


def along_line(
    table: FloatArray, members: IntArray, centre: FloatArray, u: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """Positions (K,) of landmarks ``members`` along the line through ``centre`` along unit ``u``, and their
    standard deviations (K,) in that direction, metres."""
    s = (table[members, :2] - centre) @ u
    var = table[members, 2] * u[0] ** 2 + 2 * table[members, 3] * u[0] * u[1] + table[members, 4] * u[1] ** 2
    return s, np.sqrt(np.maximum(var, 1e-6))


def lattice_phase(s: FloatArray, d: float) -> tuple[float, IntArray]:
    """Along-row position of the first upright and each landmark's slot, for spacing ``d``."""
    angle = np.angle(np.mean(np.exp(2j * np.pi * s / d)))
    offset = angle / (2 * np.pi) * d
    slots = np.rint((s - offset) / d).astype(np.int64)
    slots -= slots.min()
    first = float(np.mean(s - slots * d))
    return first, slots


def fit_model(
    table: FloatArray, members: IntArray, u0: FloatArray, orientation: int, pitch: tuple[float, float]
) -> RowModel:
    """The row through landmarks ``members``: principal line (pointing along ``u0``), Fourier spacing in
    ``pitch`` (min, max metres), phase and count."""
    pts = table[members, :2]
    centre = pts.mean(axis=0)
    _, vecs = np.linalg.eigh(np.cov((pts - centre).T))
    u = vecs[:, 1] if vecs[:, 1] @ u0 >= 0 else -vecs[:, 1]
    s, sigma = along_line(table, members, centre, u)
    period = dominant_spacing(s, sigma, min_spacing_m=pitch[0], max_spacing_m=pitch[1])
    first, slots = lattice_phase(s, period.d_m)
    return RowModel(members, centre, u, period.d_m, first, int(slots.max()) + 1, period.coherence, orientation)


def lattice_inliers(
    table: FloatArray, row: RowModel, *, max_residual_m: float = 0.15, z: float = 4.0
) -> npt.NDArray[np.bool_]:
    """Which of ``row``'s landmarks sit on its line and lattice: within ``max_residual_m`` (or ``z`` of their
    standard deviations, if more) of it across and of a lattice slot along.

    The phase is the one most landmarks agree with (each landmark's phase tried in turn), so one
    landmark far off its slot (a ghost where rays of different uprights crossed) cannot shift the
    row, as it would the mean phase.
    """
    u = row.direction
    s, sigma = along_line(table, row.members, row.centre, u)
    across = (table[row.members, :2] - row.centre) @ np.array([-u[1], u[0]])
    _, sigma_across = along_line(table, row.members, row.centre, np.array([-u[1], u[0]]))
    limit = np.maximum(max_residual_m, z * sigma)
    offsets = (s[:, None] - s[None, :] + 0.5 * row.d) % row.d - 0.5 * row.d  # phase of j relative to i
    votes = (np.abs(offsets) <= limit[None, :]).sum(axis=1)
    phase = s[int(np.argmax(votes))]
    residual = (s - phase + 0.5 * row.d) % row.d - 0.5 * row.d
    on_line = np.abs(across) <= np.maximum(max_residual_m, z * sigma_across)
    ok: npt.NDArray[np.bool_] = (np.abs(residual) <= limit) & on_line
    return ok
