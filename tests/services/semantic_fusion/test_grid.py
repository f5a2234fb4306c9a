import numpy as np
import pytest

from services.semantic_fusion import (
    SemanticFusionError,
    SemanticGrid,
    evidence_weights,
    infer_labels,
)
from services.semantic_fusion.classes import column_of
from shared.vocabulary import SemanticClass

WALL, HUMAN = column_of(SemanticClass.WALL), column_of(SemanticClass.HUMAN)


def _add(grid: SemanticGrid, xy: list[tuple[float, float]], column: int, stamp_s: float,
         confidence: float = 0.8) -> np.ndarray:
    rows = grid.rows_of(np.array(xy))
    n = rows.size
    grid.accumulate(rows, np.full(n, column), evidence_weights(np.full(n, confidence)), np.full(n, 2.0),
                    np.full(n, stamp_s))
    return rows


def test_grid_starts_uniform_and_stores_only_hit_cells() -> None:
    grid = SemanticGrid(resolution_m=0.05)
    _add(grid, [(0.01, 0.01), (0.02, 0.03), (10.0, -3.0)], WALL, 0.0)
    cells = grid.cells(now_s=0.0)
    assert grid.n_cells == 2
    hits = {tuple(rc): h for rc, h in zip(cells.rows_cols.tolist(), cells.hits.tolist(), strict=True)}
    assert hits == {(0, 0): 2.0, (-60, 200): 1.0}
    others = np.delete(cells.log_evidence, WALL, axis=1)
    assert np.all(others == 0.0)
    assert np.all(cells.log_evidence[:, WALL] > 0.0)


def test_taking_observations_out_restores_the_grid() -> None:
    rng = np.random.default_rng(1)
    grid = SemanticGrid(resolution_m=0.05)
    keep = _add(grid, [tuple(p) for p in rng.uniform(0, 1, (50, 2))], WALL, 0.0)
    before = grid.cells(now_s=5.0)
    xy = rng.uniform(0, 1, (80, 2))
    columns = rng.integers(0, 7, 80)
    weights = evidence_weights(rng.uniform(0.2, 1.0, 80))
    stamps = rng.uniform(0.0, 5.0, 80)
    rows = grid.rows_of(xy)
    grid.accumulate(rows, columns, weights, np.ones(80), stamps)
    grid.accumulate(rows, columns, weights, np.ones(80), stamps, sign=-1.0)
    after = grid.cells(now_s=5.0)
    n = before.hits.size
    assert keep.size == 50
    np.testing.assert_allclose(after.log_evidence[:n], before.log_evidence, atol=1e-4)
    np.testing.assert_allclose(after.hits[:n], before.hits, atol=1e-4)
    np.testing.assert_allclose(after.hits[n:], 0.0, atol=1e-4)


def test_dynamic_classes_decay_while_static_classes_accumulate() -> None:
    grid = SemanticGrid(resolution_m=0.05, dynamic_half_life_s=10.0)
    for t in range(5):
        _add(grid, [(0.0, 0.0)], WALL, float(t))
        _add(grid, [(1.0, 1.0)], HUMAN, float(t))
    fresh = infer_labels(grid.cells(now_s=5.0), min_hits=2.0)
    late = grid.cells(now_s=200.0)
    stale = infer_labels(late, min_hits=2.0)
    human_row = int(np.flatnonzero(late.rows_cols[:, 0] == 20)[0])
    assert sorted(fresh.labels.tolist()) == [SemanticClass.WALL, SemanticClass.HUMAN]
    assert stale.labels[human_row] == SemanticClass.NONE
    assert stale.labels[1 - human_row] == SemanticClass.WALL
    assert late.hits[1 - human_row] == pytest.approx(5.0)


def test_grid_rescales_dynamic_evidence_over_long_runs_without_overflow() -> None:
    grid = SemanticGrid(resolution_m=0.05, dynamic_half_life_s=1.0)
    for t in np.arange(0.0, 500.0, 7.0):
        _add(grid, [(0.0, 0.0)], HUMAN, float(t))
    cells = grid.cells(now_s=497.0)
    assert np.all(np.isfinite(cells.log_evidence))
    assert 1.0 < float(cells.hits[0]) < 1.01


def test_grid_rejects_mismatched_lengths_and_bad_settings() -> None:
    grid = SemanticGrid()
    rows = grid.rows_of(np.zeros((2, 2)))
    with pytest.raises(SemanticFusionError, match="differ in length"):
        grid.accumulate(rows, [0], [1.0, 1.0], [0.0, 0.0], [0.0, 0.0])
    with pytest.raises(SemanticFusionError, match="resolution_m"):
        SemanticGrid(resolution_m=0.0)
    with pytest.raises(SemanticFusionError, match="max_confidence"):
        evidence_weights([0.5], max_confidence=1.0)
