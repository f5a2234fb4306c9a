"""Grid decomposition on warehouses: label accuracy, junctions, pallet cells, speed and peak memory.

Prints ``name value unit`` lines, one BLAS thread, seconds as wall time and CPU time
(``time.process_time``) with the load average, since the machine may be shared. Every decomposition runs as the
worker and ``aisle decompose`` run it: with the cyclic garbage collector held off
(:func:`shared.collector.collector_held`) and the allocator keeping freed memory for the next arrays
(:func:`shared.heap.keep_freed_memory`, ``heap_kept_bytes`` of the settings).

* Synthetic warehouses from the seeded generator of the tests
  (``tests/services/grid_decomposition/warehouse.py``), seeds 0-2 of: ``plain`` (aisles
  2.8-3.5 m), ``narrow`` (1.8-2.2 m), ``wide`` (3.5-4.5 m), ``turned`` (the whole map rotated by
  0.3 + 0.4 * seed rad) and ``two_region`` (a second walled building whose racks are rotated by
  0.5 rad); 10 % of the uprights missing everywhere. Per map: label accuracy over free space,
  cross-aisle junctions found (the label at each junction's centre), pallet cells labelled
  corridor (a cell's majority label; also as a share of storage pixels).
* The tuw grid warehouses (``../shared/data/maps/tuw_warehouse``) with a ground truth derived from
  their grid (``tuw_truth`` of the same test helper): accuracy, junctions found (a true junction is found when most of
  its pixels are labelled junction), junction pixels found, and the regions (junction and corridor
  regions, topology links).
* A 5000 x 1440 px warehouse (250 m x 72 m at 5 cm): median of three runs.
* The ipa maps (every variant), one run each: median seconds (``--no-ipa`` skips them).
* Rack halls drawn the ways other maps draw racks (``services/simulator/rackmaps.py``), seeds 0-2,
  each straight and turned by 0.2 + 0.16 * seed rad (11-30 degrees): ``solid`` and ``uprights``
  (tuned on), ``pallet_height``, ``overhang``, ``beams``, ``mixed`` (held out) and ``depot`` (pallets
  and box stacks on open floor). Per map: free cells right, storage recall, storage labelled
  corridor, cross aisles found as junction regions (most of a junction's free pixels in one
  junction region), rack rows found (a true rack row whose centre lies in a found one of
  similar area), rooms (a depot's pallets must not make any), seconds. ``--racks-only`` runs only
  these and the large hall below.
* A 250 m x 90 m pallet-height hall at 5 cm (5000 x 1800 px): wall seconds of a fresh process
  reading it and decomposing it (start-up and imports included; the package's import and the decomposition with
  the collector held off and what the process holds then frozen, as ``aisle decompose``) and its figures.

``--overview docs/solid_rack_hall_overview.png`` writes the overview picture of a turned solid-rack
hall instead. ``--stages MAP [MAP ...]`` prints instead the CPU seconds of every step of the pipeline
(each function ``pipeline.decompose`` calls, CPU of the thread that ran it; best of three runs by
total CPU, all threads, printed with its wall seconds; ``inline`` is the rest: ``decompose``'s own
lines and what steps ran on threads of their own) for ``big_rack_hall``,
``large_warehouse``, ``rose2:<name>`` (a ROSE\u00b2 full map, read as ``eval_ipa.py`` reads it) or a
map file (0.05 m a pixel unless its YAML says otherwise). Issue 20's speed target is CPU on one core: run
``--stages`` under ``taskset -c 0`` (the ``cores`` line says how many the process had: on two, the steps that run
on a thread of their own beside the others count as CPU too).

Run from the repository root: ``PYTHONPATH=. .venv/bin/python bench/bench_grid_decomposition.py``.
"""

from __future__ import annotations

import argparse
import functools
import inspect
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np
import numpy.typing as npt
from threadpoolctl import threadpool_limits

from bench.eval_ipa import ROSE2, rose2_occupancy
from services.grid_decomposition import Decomposition, decompose, overview_image, pipeline, read_map_file
from services.simulator.rackmaps import RackMap, RackStyle, rack_hall_map
from shared.collector import collector_held
from shared.heap import keep_freed_memory
from shared.settings import get_settings
from shared.vocabulary import PlaceLabel
from tests.services.grid_decomposition.warehouse import Warehouse, cell_labels, synthetic_warehouse, tuw_truth

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "maps"
LARGE_SHAPE = (1440, 5000)


def _accuracy(labels: npt.NDArray[np.uint8], truth: npt.NDArray[np.uint8], free: npt.NDArray[np.bool_]) -> float:
    return float((labels[free] == truth[free]).mean())


def _timed(occupancy: npt.NDArray[np.int8], resolution_m: float) -> tuple[Decomposition, float, float]:
    wall, cpu = time.perf_counter(), time.process_time()
    with collector_held():  # as the worker and ``aisle decompose`` run it
        d = decompose(occupancy, resolution_m=resolution_m)
    return d, time.perf_counter() - wall, time.process_time() - cpu


def _report_warehouse(tag: str, wh: Warehouse, d: Decomposition) -> None:
    free = wh.occupancy == 0
    found = sum(d.labels[round(y), round(x)] == PlaceLabel.JUNCTION.value for x, y in wh.junctions_px)
    storage = free & (wh.truth == PlaceLabel.STORAGE.value)
    cells = cell_labels(d.labels, wh)
    print(f"{tag}_accuracy {100 * _accuracy(d.labels, wh.truth, free):.2f} %")
    print(f"{tag}_junctions_found {found}/{len(wh.junctions_px)} count")
    print(f"{tag}_cells_as_corridor {(cells == PlaceLabel.CORRIDOR.value).sum()}/{(cells >= 0).sum()} count")
    print(f"{tag}_storage_px_as_corridor {100 * (d.labels[storage] == PlaceLabel.CORRIDOR.value).mean():.2f} %")


def _synthetic() -> None:
    for seed in (0, 1, 2):
        maps = {
            "plain": synthetic_warehouse(seed),
            "narrow": synthetic_warehouse(seed, aisle_width_m=(1.8, 2.2)),
            "wide": synthetic_warehouse(seed, aisle_width_m=(3.5, 4.5)),
            "turned": synthetic_warehouse(seed, rotation_rad=0.3 + 0.4 * seed),
            "two_region": synthetic_warehouse(seed, rotated_block_rad=0.5),
        }
        for name, wh in maps.items():
            d, wall, cpu = _timed(wh.occupancy, wh.resolution_m)
            tag = f"synthetic_{name}_seed{seed}"
            _report_warehouse(tag, wh, d)
            print(f"{tag}_seconds {wall:.2f} s")
            print(f"{tag}_cpu_seconds {cpu:.2f} s")


def _tuw() -> None:
    for name in ("warehouse008", "warehouse032", "warehouse200"):
        path = DATA / "tuw_warehouse" / name / "map.yaml"
        if not path.exists():
            print(f"# {path} is absent: tuw maps skipped")
            return
        occ, res, _ = read_map_file(path)
        d, wall, cpu = _timed(occ, res)
        truth = tuw_truth(occ)
        free = occ == 0
        junction = free & (truth == PlaceLabel.JUNCTION.value)
        n, parts = cv2.connectedComponents(junction.astype(np.uint8), connectivity=4)
        hit = np.bincount(parts[junction], weights=d.labels[junction] == PlaceLabel.JUNCTION.value, minlength=n)
        size = np.bincount(parts[junction], minlength=n)
        found = int((hit[1:] > 0.5 * size[1:]).sum())
        print(f"tuw_{name}_accuracy {100 * _accuracy(d.labels, truth, free):.2f} %")
        print(f"tuw_{name}_junctions_found {found}/{n - 1} count")
        print(f"tuw_{name}_junction_px_found {100 * (d.labels[junction] == PlaceLabel.JUNCTION.value).mean():.2f} %")
        kinds = [info.label for info in d.regions.values()]
        print(f"tuw_{name}_regions {len(kinds)} count")
        print(f"tuw_{name}_junction_regions {kinds.count(PlaceLabel.JUNCTION)} count")
        print(f"tuw_{name}_corridor_regions {kinds.count(PlaceLabel.CORRIDOR)} count")
        print(f"tuw_{name}_topology_links {d.topology.number_of_edges()} count")
        print(f"tuw_{name}_seconds {wall:.2f} s")
        print(f"tuw_{name}_cpu_seconds {cpu:.2f} s")


def large_warehouse() -> Warehouse:
    """A 5000 x 1440 px warehouse at 5 cm (250 m x 72 m): 11 double rows, 4 x 21 bays, unknown border."""
    wh = synthetic_warehouse(7, n_double_rows=11, n_sections=4, bays_per_section=21, aisle_width_m=(3.2, 3.8))
    pad = [(0, t - s) for s, t in zip(wh.occupancy.shape, LARGE_SHAPE, strict=True)]
    assert min(p[1] for p in pad) >= 0, wh.occupancy.shape
    return Warehouse(
        np.pad(wh.occupancy, pad, constant_values=-1),
        np.pad(wh.truth, pad),
        np.pad(wh.cells, pad),
        wh.junctions_px,
        wh.resolution_m,
    )


def _large() -> None:
    wh = large_warehouse()
    print(f"large_warehouse_shape {wh.occupancy.shape[1]}x{wh.occupancy.shape[0]} px")
    runs = [_timed(wh.occupancy, wh.resolution_m) for _ in range(3)]
    print(f"large_warehouse_seconds {statistics.median(r[1] for r in runs):.2f} s")
    print(f"large_warehouse_cpu_seconds {statistics.median(r[2] for r in runs):.2f} s")
    _report_warehouse("large_warehouse", wh, runs[0][0])


def _ipa() -> None:
    folder = DATA / "ipa_room_segmentation"
    paths = sorted(p for p in folder.glob("*.png") if not p.name.endswith("_gt_segmentation.png"))
    if not paths:
        print(f"# {folder} is absent: ipa maps skipped")
        return
    times = [_timed(read_map_file(p, resolution_m=0.05)[0], 0.05)[1:] for p in paths]
    print(f"ipa_maps {len(paths)} count")
    print(f"ipa_median_seconds {statistics.median(t[0] for t in times):.3f} s")
    print(f"ipa_median_cpu_seconds {statistics.median(t[1] for t in times):.3f} s")
    print(f"ipa_max_seconds {max(t[0] for t in times):.2f} s")


def _rows_found(hall: RackMap, d: Decomposition) -> int:
    """True rack rows whose centre lies in a found row of area within 25 %."""
    found = 0
    for truth in hall.racks_px:
        centre = truth.mean(axis=0)
        area = cv2.contourArea(truth.astype(np.float32))
        for row in d.rack_rows_px:
            inside = cv2.pointPolygonTest(row.astype(np.float32), (float(centre[0]), float(centre[1])), False) >= 0
            if inside and abs(cv2.contourArea(row.astype(np.float32)) - area) <= 0.25 * area:
                found += 1
                break
    return found


def _junction_regions(hall: RackMap, d: Decomposition) -> int:
    """Cross-aisle junctions most of whose free pixels lie in one junction region."""
    free = hall.occupancy == 0
    found = 0
    junction_regions = np.array([k for k, r in d.regions.items() if r.label is PlaceLabel.JUNCTION], dtype=np.int64)
    for k in range(1, int(hall.junctions.max()) + 1):
        seg = d.segments[(hall.junctions == k) & free]
        if seg.size == 0:
            continue
        ids, counts = np.unique(seg, return_counts=True)
        best = ids[np.argmax(counts)]
        found += int(counts.max() > 0.5 * seg.size and best in junction_regions)
    return found


def report_rack_hall(tag: str, hall: RackMap, d: Decomposition) -> None:
    """Print the rack-hall figures of one decomposition."""
    free = hall.occupancy == 0
    storage = free & (hall.truth == PlaceLabel.STORAGE.value)
    kinds = [info.label for info in d.regions.values()]
    print(f"{tag}_accuracy {100 * _accuracy(d.labels, hall.truth, free):.2f} %")
    if storage.any():
        print(f"{tag}_storage_recall {100 * (d.labels[storage] == PlaceLabel.STORAGE.value).mean():.2f} %")
        print(f"{tag}_storage_as_corridor {100 * (d.labels[storage] == PlaceLabel.CORRIDOR.value).mean():.2f} %")
    floor = free & (hall.truth == PlaceLabel.OPEN_AREA.value)
    if floor.any():
        print(f"{tag}_open_floor_as_storage {100 * (d.labels[floor] == PlaceLabel.STORAGE.value).mean():.2f} %")
    print(f"{tag}_junction_regions {_junction_regions(hall, d)}/{int(hall.junctions.max())} count")
    print(f"{tag}_rack_rows_found {_rows_found(hall, d)}/{len(hall.racks_px)} count")
    print(f"{tag}_rooms {kinds.count(PlaceLabel.ROOM)} count")


RACK_SETS = {
    "solid": RackStyle.SOLID,
    "uprights": RackStyle.UPRIGHTS,
    "pallet_height": RackStyle.PALLET_HEIGHT,
    "overhang": RackStyle.OVERHANG,
    "beams": RackStyle.BEAMS,
    "mixed": RackStyle.MIXED,
    "depot": RackStyle.DEPOT,
}


def _rack_halls() -> None:
    for name, style in RACK_SETS.items():
        for seed in (0, 1, 2):
            for turned in (False, True):
                rotation = 0.2 + 0.16 * seed if turned else 0.0
                hall = rack_hall_map(seed, style=style, rotation_rad=rotation)
                d, wall, cpu = _timed(hall.occupancy, hall.resolution_m)
                tag = f"racks_{name}{'_turned' if turned else ''}_seed{seed}"
                report_rack_hall(tag, hall, d)
                print(f"{tag}_seconds {wall:.2f} s")
                print(f"{tag}_cpu_seconds {cpu:.2f} s")


def big_rack_hall() -> RackMap:
    """250 m x 90 m pallet-height hall at 5 cm: 16 double rows, 4 sections of 22 bays."""
    return rack_hall_map(
        11, style=RackStyle.PALLET_HEIGHT, n_double_rows=16, n_sections=4, bays_per_section=22,
        aisle_width_m=(2.9, 3.2), margin_m=0.5,
    )


_CHILD = """
import gc, sys, time, numpy as np
from threadpoolctl import threadpool_limits
from shared.collector import collector_held
from shared.heap import keep_freed_memory
from shared.settings import get_settings
keep_freed_memory(get_settings().heap_kept_bytes)  # as the aisle command sets it
occ = np.load(sys.argv[1])
with threadpool_limits(1), collector_held():  # as aisle decompose runs it
    from services.grid_decomposition import decompose
    d = decompose(occ, resolution_m=0.05)
    np.save(sys.argv[2], d.labels)
    np.save(sys.argv[3], d.segments)
    gc.freeze()
"""


def _big_rack_hall() -> None:
    hall = big_rack_hall()
    h, w = hall.occupancy.shape
    print(f"big_rack_hall_shape {w}x{h} px")
    with tempfile.TemporaryDirectory() as tmp:
        occ, lab, seg = (Path(tmp) / n for n in ("occ.npy", "labels.npy", "segments.npy"))
        np.save(occ, hall.occupancy)
        wall = time.perf_counter()
        subprocess.run([sys.executable, "-c", _CHILD, str(occ), str(lab), str(seg)], check=True)
        wall = time.perf_counter() - wall
        labels = np.load(lab)
    print(f"big_rack_hall_process_seconds {wall:.2f} s")
    free = hall.occupancy == 0
    storage = free & (hall.truth == PlaceLabel.STORAGE.value)
    print(f"big_rack_hall_accuracy {100 * _accuracy(labels, hall.truth, free):.2f} %")
    print(f"big_rack_hall_storage_recall {100 * (labels[storage] == PlaceLabel.STORAGE.value).mean():.2f} %")
    print(f"big_rack_hall_storage_as_corridor {100 * (labels[storage] == PlaceLabel.CORRIDOR.value).mean():.2f} %")


def _stage_map(name: str) -> tuple[npt.NDArray[np.int8], float]:
    if name == "big_rack_hall":
        hall = big_rack_hall()
        return hall.occupancy, hall.resolution_m
    if name == "large_warehouse":
        wh = large_warehouse()
        return wh.occupancy, wh.resolution_m
    if name.startswith("rose2:"):
        from PIL import Image

        with Image.open(ROSE2 / "full" / name.removeprefix("rose2:") / "map.png") as image:
            return rose2_occupancy(np.asarray(image.convert("L"))), 0.05
    occ, res, _ = read_map_file(Path(name), resolution_m=0.05)
    return occ, res


def stage_seconds(occupancy: npt.NDArray[np.int8], resolution_m: float) -> dict[str, float]:
    """CPU seconds of one decomposition (``total``, every thread) and of each function ``decompose`` calls, by name.

    A step's seconds are those of the thread that ran it (some run on a second thread beside the
    others); ``wall`` is the decomposition's wall time.
    """
    seconds: dict[str, float] = {}
    depth = threading.local()

    def timed(name: str, fn: Callable[..., object]) -> Callable[..., object]:
        @functools.wraps(fn)
        def run(*args: object, **kwargs: object) -> object:
            depth.n = getattr(depth, "n", 0) + 1
            start = time.thread_time()
            try:
                return fn(*args, **kwargs)
            finally:
                depth.n -= 1
                if depth.n == 0:  # a step, not a step inside another
                    seconds[name] = seconds.get(name, 0.0) + time.thread_time() - start
        return run

    steps = {
        name: fn
        for name, fn in vars(pipeline).items()
        if inspect.isfunction(fn) and name != "decompose" and fn.__module__.startswith("services.")
    }
    try:
        for name, fn in steps.items():
            setattr(pipeline, name, timed(name, fn))
        start, wall = time.process_time(), time.perf_counter()
        with collector_held():  # as the worker and ``aisle decompose`` run it
            pipeline.decompose(occupancy, resolution_m=resolution_m)
        seconds["total"] = time.process_time() - start
        seconds["wall"] = time.perf_counter() - wall
    finally:
        for name, fn in steps.items():
            setattr(pipeline, name, fn)
    return seconds


def _stages(names: list[str]) -> None:
    for name in names:
        occ, res = _stage_map(name)
        runs = [stage_seconds(occ, res) for _ in range(3)]
        best = min(runs, key=lambda r: r["total"])
        tag = name.replace("rose2:", "rose2_").replace("/", "_").replace(".", "_")
        print(f"stages_{tag}_cores {len(os.sched_getaffinity(0))} cores")
        print(f"stages_{tag}_total_cpu_seconds {best['total']:.3f} s")
        print(f"stages_{tag}_wall_seconds {best['wall']:.3f} s")
        rest = best["total"] - sum(v for k, v in best.items() if k not in ("total", "wall"))
        for step, value in sorted(best.items(), key=lambda kv: -kv[1]):
            if step not in ("total", "wall"):
                print(f"stages_{tag}_{step}_cpu_seconds {value:.3f} s")
        print(f"stages_{tag}_inline_cpu_seconds {rest:.3f} s")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--no-ipa", action="store_true", help="skip the ipa timings")
    parser.add_argument("--racks-only", action="store_true", help="only the rack-hall sets and the big rack hall")
    parser.add_argument("--overview", type=Path, help="write the overview picture of a solid-rack hall here and stop")
    parser.add_argument("--stages", nargs="+", metavar="MAP", help="print CPU seconds per pipeline step and stop")
    args = parser.parse_args()
    keep_freed_memory(get_settings().heap_kept_bytes)  # as the aisle command sets it for every stage
    if args.stages:
        with threadpool_limits(1):
            _stages(args.stages)
        return
    if args.overview:
        hall = rack_hall_map(1, style=RackStyle.SOLID, rotation_rad=0.35, n_double_rows=5, n_sections=3)
        picture = overview_image(decompose(hall.occupancy, resolution_m=hall.resolution_m))
        cv2.imwrite(str(args.overview), cv2.cvtColor(picture, cv2.COLOR_RGB2BGR))
        return
    print(f"load_average_start {os.getloadavg()[0]:.2f} ratio")
    with threadpool_limits(1):
        if not args.racks_only:
            _synthetic()
            _tuw()
            _large()
            if not args.no_ipa:
                _ipa()
        _rack_halls()
        _big_rack_hall()
    print(f"load_average_end {os.getloadavg()[0]:.2f} ratio")
    print(f"peak_rss {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f} MiB")


if __name__ == "__main__":
    main()
