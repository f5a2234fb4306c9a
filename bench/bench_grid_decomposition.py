"""Grid decomposition: speed, peak memory and label accuracy on synthetic and real warehouses.

Prints ``name value unit`` lines. Synthetic warehouses come from the seeded generator of the
tests (``tests/services/grid_decomposition/warehouse.py``); the tuw grid warehouses get a
ground truth derived from their grid (a free pixel whose free runs along both axes are longer
than 1.5 road widths is a junction, else corridor). Run from the repository root with
``PYTHONPATH=. .venv/bin/python bench/bench_grid_decomposition.py`` (one BLAS thread).
"""

from __future__ import annotations

import resource
import time
from pathlib import Path

import numpy as np
import numpy.typing as npt
from threadpoolctl import threadpool_limits

from services.grid_decomposition import Label, decompose, read_map_file
from tests.services.grid_decomposition.warehouse import synthetic_warehouse

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "maps"


def _runs(free: npt.NDArray[np.bool_]) -> npt.NDArray[np.int64]:
    """Length of the horizontal free run through every pixel."""
    out = np.zeros(free.shape, dtype=np.int64)
    for r in range(free.shape[0]):
        row = free[r].astype(np.int8)
        d = np.diff(np.r_[0, row, 0])
        starts, ends = np.flatnonzero(d == 1), np.flatnonzero(d == -1)
        for a, b in zip(starts, ends, strict=True):
            out[r, a:b] = b - a
    return out


def tuw_truth(occupancy: npt.NDArray[np.int8]) -> npt.NDArray[np.uint8]:
    """Corridor / junction ground truth of a tuw grid warehouse (roads between solid blocks)."""
    free = occupancy == 0
    h_run, v_run = _runs(free), _runs(free.T).T
    road = int(np.bincount(np.minimum(h_run, v_run)[free]).argmax())
    truth = np.where(free, Label.CORRIDOR.value, 0).astype(np.uint8)
    truth[free & (h_run > 1.5 * road) & (v_run > 1.5 * road)] = Label.JUNCTION.value
    return truth


def _accuracy(labels: npt.NDArray[np.uint8], truth: npt.NDArray[np.uint8], free: npt.NDArray[np.bool_]) -> float:
    return float((labels[free] == truth[free]).mean())


def _synthetic(tag: str, seed: int, rotated: float | None) -> None:
    wh = synthetic_warehouse(seed, rotated_block_rad=rotated)
    start = time.perf_counter()
    d = decompose(wh.occupancy, resolution_m=wh.resolution_m)
    seconds = time.perf_counter() - start
    free = wh.occupancy == 0
    found = sum(d.labels[round(y), round(x)] == Label.JUNCTION.value for x, y in wh.junctions_px)
    storage = free & (wh.truth == Label.STORAGE.value)
    print(f"synthetic_{tag}_seed{seed}_accuracy {100 * _accuracy(d.labels, wh.truth, free):.2f} %")
    print(f"synthetic_{tag}_seed{seed}_junctions_found {found}/{len(wh.junctions_px)} count")
    print(f"synthetic_{tag}_seed{seed}_storage_as_corridor {100 * (d.labels[storage] == 1).mean():.2f} %")
    print(f"synthetic_{tag}_seed{seed}_seconds {seconds:.2f} s")


def main() -> None:
    with threadpool_limits(1):
        for seed in (0, 1, 2):
            _synthetic("plain", seed, None)
            _synthetic("rotated", seed, 0.5)
        for name in ("warehouse008", "warehouse032", "warehouse200"):
            path = DATA / "tuw_warehouse" / name / "map.yaml"
            if not path.exists():
                continue
            occ, res, origin = read_map_file(path)
            start = time.perf_counter()
            d = decompose(occ, resolution_m=res, origin_xy_m=origin)
            seconds = time.perf_counter() - start
            truth = tuw_truth(occ)
            free = occ == 0
            print(f"tuw_{name}_accuracy {100 * _accuracy(d.labels, truth, free):.2f} %")
            junction = free & (truth == Label.JUNCTION.value)
            print(f"tuw_{name}_junction_recall {100 * (d.labels[junction] == 2).mean():.2f} %")
            print(f"tuw_{name}_seconds {seconds:.2f} s")
        big = synthetic_warehouse(7, n_double_rows=11, n_sections=5, bays_per_section=16)
        print(f"large_warehouse_shape {big.occupancy.shape[1]}x{big.occupancy.shape[0]} px")
        start = time.perf_counter()
        d = decompose(big.occupancy, resolution_m=big.resolution_m)
        print(f"large_warehouse_seconds {time.perf_counter() - start:.2f} s")
        free = big.occupancy == 0
        print(f"large_warehouse_accuracy {100 * _accuracy(d.labels, big.truth, free):.2f} %")
    print(f"peak_rss {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f} MiB")


if __name__ == "__main__":
    main()
