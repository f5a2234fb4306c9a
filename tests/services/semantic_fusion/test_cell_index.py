import numpy as np

from services.semantic_fusion.cell_index import CellIndex


def test_cell_index_keeps_rows_stable_across_merges() -> None:
    rng = np.random.default_rng(0)
    index = CellIndex(merge_at=50)
    seen: dict[int, int] = {}
    for _ in range(40):
        keys = np.unique(rng.integers(-10**12, 10**12, 30) // 10**9)
        rows = index.rows(keys)
        for k, r in zip(keys.tolist(), rows.tolist(), strict=True):
            assert seen.setdefault(k, r) == r
    assert len(index) == len(seen)
    assert sorted(seen.values()) == list(range(len(seen)))
