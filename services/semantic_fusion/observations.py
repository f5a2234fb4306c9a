"""Labelled points attached to keyframes, in each keyframe's own frame.

Scans only ever attach to the newest keyframe, so the points of keyframe ``k`` are one contiguous
slice of columnar arrays that double in capacity as they fill. Each point also remembers the grid
row it was last added to, so re-projection can take it out again without looking the cell up.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import numpy.typing as npt

from services.semantic_fusion.errors import SemanticFusionError


class PointBatch(NamedTuple):
    """Columns of some attached points: keyframe-frame ``xy`` (n, 2) float32 metres, ``columns`` (n,)
    uint8, ``weights`` (n,) float32 log-evidence, ``heights`` (n,) float32 metres, ``stamps_s`` (n,)
    float64 seconds, ``rows`` (n,) int64 grid rows, ``keyframes`` (n,) int64."""

    xy: npt.NDArray[np.float32]
    columns: npt.NDArray[np.uint8]
    weights: npt.NDArray[np.float32]
    heights: npt.NDArray[np.float32]
    stamps_s: npt.NDArray[np.float64]
    rows: npt.NDArray[np.int64]
    keyframes: npt.NDArray[np.int64]


_DTYPES = {"xy": np.float32, "columns": np.uint8, "weights": np.float32, "heights": np.float32,
           "stamps": np.float32, "rows": np.int32}


class ObservationStore:
    """Columnar store of attached points; stamps are kept as float32 seconds after ``epoch_s``."""

    def __init__(self, *, initial_points: int = 1 << 16) -> None:
        n = max(16, initial_points)
        self._cols: dict[str, npt.NDArray[np.generic]] = {
            name: np.zeros((n, 2) if name == "xy" else n, dtype=dtype) for name, dtype in _DTYPES.items()
        }
        self._size = 0
        self._starts: list[int] = []
        self._epoch_s: float | None = None

    @property
    def n_points(self) -> int:
        """Points attached."""
        return self._size

    @property
    def n_keyframes(self) -> int:
        """Keyframes started."""
        return len(self._starts)

    @property
    def nbytes(self) -> int:
        """Memory held by the columns, bytes."""
        return int(sum(col.nbytes for col in self._cols.values()))

    def start_keyframe(self) -> int:
        """Begin the next keyframe; later :meth:`append` calls attach to it. Returns its index."""
        self._starts.append(self._size)
        return len(self._starts) - 1

    def append(self, xy: npt.ArrayLike, columns: npt.ArrayLike, weights: npt.ArrayLike, heights: npt.ArrayLike,
               stamp_s: float, rows: npt.ArrayLike) -> None:
        """Attach points of one scan (keyframe frame) to the newest keyframe."""
        if not self._starts:
            raise SemanticFusionError("no keyframe to attach points to: call start_keyframe first")
        pts = np.asarray(xy).reshape(-1, 2)
        n = pts.shape[0]
        if self._epoch_s is None:
            self._epoch_s = stamp_s
        end = self._size + n
        if end > self._cols["columns"].shape[0]:
            capacity = self._cols["columns"].shape[0]
            while capacity < end:
                capacity *= 2
            for name, col in self._cols.items():
                grown = np.zeros((capacity, *col.shape[1:]), dtype=col.dtype)
                grown[: self._size] = col[: self._size]
                self._cols[name] = grown
        sl = slice(self._size, end)
        self._cols["xy"][sl] = pts
        self._cols["columns"][sl] = np.asarray(columns).reshape(-1)
        self._cols["weights"][sl] = np.asarray(weights).reshape(-1)
        self._cols["heights"][sl] = np.asarray(heights).reshape(-1)
        self._cols["stamps"][sl] = stamp_s - self._epoch_s
        self._cols["rows"][sl] = np.asarray(rows).reshape(-1)
        self._size = end

    def _index(self, keyframes: npt.NDArray[np.int64]) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int64]]:
        bounds = np.append(np.asarray(self._starts, dtype=np.int64), self._size)
        starts, ends = bounds[keyframes], bounds[keyframes + 1]
        lengths = ends - starts
        owner = np.repeat(keyframes, lengths)
        offsets = np.arange(int(lengths.sum()), dtype=np.int64) - np.repeat(np.cumsum(lengths) - lengths, lengths)
        return np.repeat(starts, lengths) + offsets, owner

    def batch(self, keyframes: npt.ArrayLike) -> PointBatch:
        """The points of the given keyframes (ascending order not required)."""
        kf = np.asarray(keyframes, dtype=np.int64).reshape(-1)
        if kf.size and (kf.min() < 0 or kf.max() >= len(self._starts)):
            raise SemanticFusionError(f"keyframes must be in 0..{len(self._starts) - 1}")
        idx, owner = self._index(kf)
        c = self._cols
        epoch = self._epoch_s or 0.0
        return PointBatch(c["xy"][idx].astype(np.float32), c["columns"][idx].astype(np.uint8),
                          c["weights"][idx].astype(np.float32), c["heights"][idx].astype(np.float32),
                          c["stamps"][idx].astype(np.float64) + epoch, c["rows"][idx].astype(np.int64), owner)

    def set_rows(self, keyframes: npt.ArrayLike, rows: npt.ArrayLike) -> None:
        """Record new grid rows for the points of ``keyframes``, in :meth:`batch` order."""
        idx, _ = self._index(np.asarray(keyframes, dtype=np.int64).reshape(-1))
        self._cols["rows"][idx] = np.asarray(rows).reshape(-1)
