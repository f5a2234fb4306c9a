"""A compact map from int64 cell keys to storage rows: a sorted array plus a small dict of recent keys.

A Python dict holding every cell of a large hall costs about 100 bytes a cell; here settled keys live
in two sorted int64 arrays (16 bytes a cell, looked up with ``np.searchsorted``) and only keys added
since the last merge sit in a dict, which is folded into the arrays when it grows past ``merge_at``.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt


class CellIndex:
    """Key -> row map; rows are handed out 0, 1, 2, ... in order of first sight."""

    def __init__(self, *, merge_at: int = 65536) -> None:
        self._keys = np.empty(0, dtype=np.int64)
        self._rows = np.empty(0, dtype=np.int64)
        self._recent: dict[int, int] = {}
        self._merge_at = merge_at

    def __len__(self) -> int:
        return int(self._keys.size) + len(self._recent)

    @property
    def nbytes(self) -> int:
        """Approximate memory held, bytes."""
        return int(self._keys.nbytes + self._rows.nbytes + 100 * len(self._recent))

    def rows(self, unique_keys: npt.NDArray[np.int64]) -> npt.NDArray[np.int64]:
        """Row of each of the sorted, distinct ``unique_keys``, adding rows for unseen keys."""
        out = np.full(unique_keys.size, -1, dtype=np.int64)
        if self._keys.size:
            at = np.minimum(np.searchsorted(self._keys, unique_keys), self._keys.size - 1)
            found = self._keys[at] == unique_keys
            out[found] = self._rows[at[found]]
        else:
            found = np.zeros(unique_keys.size, dtype=bool)
        rest = np.flatnonzero(~found)
        if rest.size:
            get = self._recent.get
            out[rest] = np.fromiter((get(k, -1) for k in unique_keys[rest].tolist()), dtype=np.int64,
                                    count=rest.size)
            new = rest[out[rest] < 0]
            if new.size:
                first = len(self)
                out[new] = np.arange(first, first + new.size)
                self._recent.update(zip(unique_keys[new].tolist(), out[new].tolist(), strict=True))
                if len(self._recent) >= self._merge_at:
                    self._merge()
        return out

    def _merge(self) -> None:
        keys = np.fromiter(self._recent.keys(), dtype=np.int64, count=len(self._recent))
        rows = np.fromiter(self._recent.values(), dtype=np.int64, count=len(self._recent))
        all_keys = np.concatenate([self._keys, keys])
        order = np.argsort(all_keys, kind="stable")
        self._keys, self._rows = all_keys[order], np.concatenate([self._rows, rows])[order]
        self._recent = {}
