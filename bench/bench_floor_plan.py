"""Floor plan (seed 003, chapter 3) on real maps: K(W,M), iterations/s and rooms as the ipa protocol scores them.

Prints a Markdown table per set and ``name value unit`` lines, one BLAS thread, seconds as wall time and
CPU time (``time.process_time``) with the load average, since the machine may be shared.

* ``rose2``: the ROSE\u00b2 full maps (``../shared/data/maps/rose2/full``, 0.05 m/px), read as ``aisle floor-plan
  MAP.png --resolution 0.05`` reads a bare image (map_server's thresholds, but the map's own unknown grey and the
  speckle nearer it than white are unknown, :func:`shared.mapfiles.unknown_greys`, and walls drawn light grey are
  occupied, :func:`shared.mapfiles.grey_walls`): K(W,M) (eq. 3.39, every cell of
  the map), K of the same world under the earlier fixed reading (free = grey >= 250, occupied <= 89, the rest
  unknown), K over known cells, and
  ``units.png`` and ``rooms.png`` scored as ``bench/eval_ipa.py`` scores segmentations of these maps (free pixels
  only, each ground-truth colour one room), beside ROSE\u00b2's own ``rose2_rooms.png``; and where K is lost (shares of
  all cells): free cells not drawn free, unknown cells drawn free, occupied cells not drawn as wall, and the
  cells inside the ground truth's rooms that are not free in the map (no room-shaped unit draws them right).
* ``ipa``: the ipa maps (plain, and the variants ``--variants`` names, e.g. ``_furnitures``) read as
  ``aisle floor-plan MAP.png --resolution 0.05`` reads them; K(W,M), K of the same world under map_server's fixed
  trinary reading (which reads Freiburg52's light-grey walls as free), K of the units alone (no clutter
  obstacles), and the ipa scores (every labelled pixel counts) of units and rooms, with the means over the two
  halves: the room level (``RoomSettings``) was tuned on the maps at even places in name order (``tuning``), the
  others are held out (``held_out``).
* ``partial``: the 15 growing ubremen maps in order, each warm-started from the previous world; the share
  of units of map k that keep their id in map k+1 (same rectangle after the map's shift, or the unit
  with the most overlap), and the seconds of each warm update.

``--seeds`` runs every map once per chain seed (``ChainSettings.seed``, 0 by default) and prints, besides each seed's
figures (``..._seed<S>_...``), their mean over the seeds and the range of the seeds' means (``..._seeds_...``);
``--trace-max-m`` sets ``FloorPlanSettings.trace_max_m`` (``none``: every free cell is free).
``--restarts`` sets ``ChainSettings.restarts`` (independent chains of a cold fit, the highest posterior kept).

Run: ``PYTHONPATH=. .venv/bin/python bench/bench_floor_plan.py [--sets rose2 ipa partial] [--iterations N]
[--seeds 0 1 2 3] [--trace-max-m none|0.15] [--restarts N]``.
"""

from __future__ import annotations

import argparse
import os
import statistics
import time
from pathlib import Path
from typing import NamedTuple

import numpy as np
import numpy.typing as npt
from PIL import Image
from threadpoolctl import threadpool_limits

from services.floor_plan import (
    ChainSettings,
    FloorPlan,
    FloorPlanSettings,
    World,
    carry,
    cell_prediction_rate,
    classify_map,
    floor_plan,
    make_frame,
    room_labels,
    unit_labels,
)
from services.floor_plan.mapfile import read_map
from services.grid_decomposition.evaluation import (
    FREE_GREY,
    align_offset,
    colour_rooms,
    ground_truth_rooms,
    ipa_scores,
    on_free,
)
from shared.mapfiles import read_map_file

MAPS = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "maps"
IPA = MAPS / "ipa_room_segmentation"
ROSE2 = MAPS / "rose2"
RES = 0.05
OCCUPIED_GREY = 89
WHITE = ((0, 0, 0), (255, 255, 255))


class Run(NamedTuple):
    """What every floor plan of a bench run shares: chain length, seed and the traces' reading."""

    iterations: int
    seed: int
    trace_max_m: float | None
    restarts: int


class Row(NamedTuple):
    k: float
    k_fixed: float  # K(W,M) of the same world against the map read with fixed thresholds
    k_units: float  # K(W,M) of the seed's world alone (no clutter obstacles)
    k_known: float
    recall: float  # units
    precision: float
    room_recall: float
    room_precision: float
    seconds: float
    cpu: float
    rate: float  # iterations per wall second
    cpu_rate: float  # iterations per CPU second of the chain


def _grey(path: Path) -> npt.NDArray[np.uint8]:
    with Image.open(path) as image:
        return np.asarray(image.convert("L"))


def _rgb(path: Path) -> npt.NDArray[np.uint8]:
    with Image.open(path) as image:
        return np.asarray(image.convert("RGB"))


def rose2_occupancy(grey: npt.NDArray[np.uint8]) -> npt.NDArray[np.int8]:
    occ = np.full(grey.shape, -1, dtype=np.int8)
    occ[grey >= FREE_GREY] = 0
    occ[grey <= OCCUPIED_GREY] = 100
    return occ[::-1].copy()


def _plan(occ: npt.NDArray[np.int8], run: Run, start: World | None = None,
          angle_rad: float | None = None) -> tuple[FloorPlan, float, float]:
    settings = FloorPlanSettings(chain=ChainSettings(iterations=run.iterations, max_seconds=600.0, seed=run.seed,
                                                     restarts=run.restarts),
                                 trace_max_m=run.trace_max_m)
    t0, c0 = time.perf_counter(), time.process_time()
    plan = floor_plan(occ, resolution_m=RES, settings=settings, start=start, angle_rad=angle_rad)
    return plan, time.perf_counter() - t0, time.process_time() - c0


def _k_fixed(plan: FloorPlan, occ: npt.NDArray[np.int8]) -> float:
    """K(W,M) of the plan's world against another reading of the same map."""
    return cell_prediction_rate(classify_map(occ), plan.classes_world)


def _k_known(plan: FloorPlan) -> float:
    known = plan.classes_map != 1
    return float(np.mean(plan.classes_map[known] == plan.classes_world[known]))


def _lost(plan: FloorPlan) -> tuple[float, float, float]:
    """Where K(W,M) is lost, as shares of all cells: free cells the world does not draw free, unknown
    cells it draws free, occupied cells it does not draw as wall."""
    cm, cw = plan.classes_map, plan.classes_world
    return (float(np.mean((cm == 0) & (cw != 0))), float(np.mean((cm == 1) & (cw == 0))),
            float(np.mean((cm == 2) & (cw != 2))))


def _result(plan: FloorPlan, fixed: npt.NDArray[np.int8], units: tuple[float, float], rooms: tuple[float, float],
            seconds: float, cpu: float) -> Row:
    """A row of figures: ``fixed`` is the map read with fixed thresholds (for K under that reading), ``units`` and
    ``rooms`` the (recall, precision) of units.png and rooms.png."""
    return Row(plan.k, _k_fixed(plan, fixed), plan.k_units, _k_known(plan), *units, *rooms, seconds, cpu,
               plan.iterations / max(seconds, 1e-9), plan.iterations / max(plan.cpu_seconds, 1e-9))


def _common(*images: npt.NDArray[np.generic]) -> list[npt.NDArray[np.generic]]:
    h = min(i.shape[0] for i in images)
    w = min(i.shape[1] for i in images)
    return [i[:h, :w] for i in images]


def _header() -> None:
    print("\n| set | map | K(W,M) % | K fixed reading % | K units alone % | K known % | units recall % "
          "| units precision % | rooms recall % | rooms precision % "
          "| units | rooms | doors | it/s | it/CPU s | s | CPU s |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")


def _row(tag: str, name: str, plan: FloorPlan, r: Row) -> None:
    print(f"| {tag} | {name} | {100 * r.k:.1f} | {100 * r.k_fixed:.1f} | {100 * r.k_units:.1f} | "
          f"{100 * r.k_known:.1f} | "
          f"{100 * r.recall:.1f} | {100 * r.precision:.1f} | {100 * r.room_recall:.1f} | "
          f"{100 * r.room_precision:.1f} | "
          f"{len(plan.units)} | {len(plan.rooms)} | {len(plan.doors)} | {r.rate:.0f} | {r.cpu_rate:.0f} | "
          f"{r.seconds:.1f} | {r.cpu:.1f} |")


FIELDS = ("k", "k_fixed", "k_units", "k_known", "recall", "precision", "room_recall", "room_precision")


def _seed_tag(tag: str, seed: int, seeds: list[int]) -> str:
    """Tags of one seed's figures: as before with a single seed, ``<tag>_seed<S>`` with several."""
    return tag if len(seeds) == 1 else f"{tag}_seed{seed}"


def _over_seeds(tag: str, by_seed: dict[int, list[Row]]) -> None:
    """Each figure's mean over the maps, as the mean over the seeds and the range of the seeds' values."""
    if len(by_seed) < 2 or not all(by_seed.values()):
        return
    for field in FIELDS:
        for stat, reduce in (("mean", statistics.fmean), ("min", min)):
            values = [reduce(getattr(r, field) for r in rows) for rows in by_seed.values()]
            print(f"{tag}_seeds_{field}_{stat} {100 * statistics.fmean(values):.2f} % "
                  f"(seeds {100 * min(values):.2f}..{100 * max(values):.2f})")


def _summary(tag: str, rows: list[Row]) -> None:
    if not rows:
        return
    for field in FIELDS:
        values = [getattr(r, field) for r in rows]
        print(f"{tag}_{field}_mean {100 * statistics.fmean(values):.2f} %")
        print(f"{tag}_{field}_min {100 * min(values):.2f} %")
    print(f"{tag}_iterations_per_second_median {statistics.median(r.rate for r in rows):.0f} 1/s")
    print(f"{tag}_iterations_per_cpu_second_median {statistics.median(r.cpu_rate for r in rows):.0f} 1/s")
    print(f"{tag}_cpu_seconds_median {statistics.median(r.cpu for r in rows):.2f} s")


def _rose2(run: Run, only: list[str] | None, seeds: list[int]) -> None:
    by_seed: dict[int, list[Row]] = {}
    by_map: dict[str, list[Row]] = {}
    for seed in seeds:
        by_seed[seed] = _rose2_seed(run._replace(seed=seed), only, _seed_tag("rose2", seed, seeds), by_map)
    _over_seeds("rose2", by_seed)
    if len(seeds) > 1:
        for name, rows in by_map.items():
            for field in ("k", "room_recall", "room_precision"):
                values = [100 * getattr(r, field) for r in rows]
                print(f"rose2_{name}_seeds_{field} {statistics.fmean(values):.2f} % (seeds "
                      + " ".join(f"{v:.2f}" for v in values) + ")")


def _rose2_seed(run: Run, only: list[str] | None, tag: str, by_map: dict[str, list[Row]]) -> list[Row]:
    _header()
    rows: list[Row] = []
    peers = []
    for folder in sorted(p for p in (ROSE2 / "full").iterdir() if p.is_dir()):
        if only and folder.name not in only:
            continue
        grey = _grey(folder / "map.png")
        occ, _, _ = read_map(folder / "map.png", resolution_m=RES)
        plan, seconds, cpu = _plan(occ, run)
        units = np.ascontiguousarray(unit_labels(plan)[::-1])
        cut, gt, theirs, ours, ours_rooms = _common(grey, _rgb(folder / "gt.png"), _rgb(folder / "rose2_rooms.png"),
                                                    units, np.ascontiguousarray(room_labels(plan)[::-1]))
        free = np.asarray(cut) >= FREE_GREY
        rooms = on_free(colour_rooms(np.asarray(gt)), free)
        s = ipa_scores(on_free(np.asarray(ours), free), rooms)
        sr = ipa_scores(on_free(np.asarray(ours_rooms), free), rooms)
        peer = ipa_scores(on_free(colour_rooms(np.asarray(theirs), background=WHITE), free), rooms)
        peers.append(peer)
        in_rooms = np.count_nonzero((colour_rooms(np.asarray(gt)) > 0) & ~free) / grey.size
        free_lost, unknown_free, wall_lost = _lost(plan)
        print(f"| rose2_lost | {folder.name} | free not drawn free {100 * free_lost:.1f} % | unknown drawn free "
              f"{100 * unknown_free:.1f} % | occupied not drawn as wall {100 * wall_lost:.1f} % | not free inside the "
              f"truth's rooms {100 * in_rooms:.1f} % | | | | | | |")
        r = _result(plan, rose2_occupancy(grey), (s.recall, s.precision), (sr.recall, sr.precision), seconds, cpu)
        rows.append(r)
        by_map.setdefault(folder.name, []).append(r)
        _row(tag, folder.name, plan, r)
        print(f"| rose2_peer | {folder.name} | | | | | | | {100 * peer.recall:.1f} | {100 * peer.precision:.1f} "
              "| | | | | | | |")
    _summary(tag, rows)
    if peers:
        print(f"rose2_peer_recall_mean {100 * statistics.fmean(p.recall for p in peers):.2f} %")
        print(f"rose2_peer_precision_mean {100 * statistics.fmean(p.precision for p in peers):.2f} %")
    return rows


def _ipa(run: Run, only: list[str] | None, variants: list[str], seeds: list[int]) -> None:
    by_seed: dict[str, dict[int, list[Row]]] = {variant: {} for variant in variants}
    for seed in seeds:  # every variant at one seed before the next seed: a run cut short has whole seeds
        for variant in variants:
            tag = _seed_tag(f"ipa_{variant.strip('_') or 'plain'}", seed, seeds)
            by_seed[variant][seed] = _ipa_seed(run._replace(seed=seed), only, variant, tag)
    for variant in variants:
        _over_seeds(f"ipa_{variant.strip('_') or 'plain'}", by_seed[variant])


def _ipa_seed(run: Run, only: list[str] | None, variant: str, tag: str) -> list[Row]:
    names = sorted(p.name[: -len("_gt_segmentation.png")] for p in IPA.glob("*_gt_segmentation.png"))
    tuning = set(names[0::2])
    _header()
    rows: dict[str, list[Row]] = {"tuning": [], "held_out": []}
    for name in names:
        path = IPA / f"{name}{variant}.png"
        if (only and name not in only) or not path.exists():
            continue
        truth = ground_truth_rooms(_grey(IPA / f"{name}_gt_segmentation.png"))
        occ, _, _ = read_map(path, resolution_m=RES)
        if occ.shape != truth.shape:
            continue
        plan, seconds, cpu = _plan(occ, run)
        s = ipa_scores(np.ascontiguousarray(unit_labels(plan)[::-1]), truth)
        sr = ipa_scores(np.ascontiguousarray(room_labels(plan)[::-1]), truth)
        fixed = read_map_file(path, resolution_m=RES).occupancy
        r = _result(plan, fixed, (s.recall, s.precision), (sr.recall, sr.precision), seconds, cpu)
        rows["tuning" if name in tuning else "held_out"].append(r)
        _row(tag, name, plan, r)
    _summary(tag, rows["tuning"] + rows["held_out"])
    for half, part in rows.items():
        for field in ("room_recall", "room_precision"):
            if part:
                print(f"{tag}_{half}_{field}_mean {100 * statistics.fmean(getattr(r, field) for r in part):.2f} %")
    return rows["tuning"] + rows["held_out"]


def _partial(run: Run, warm_iterations: int) -> None:
    steps = sorted((p for p in (ROSE2 / "partial_ubremen").iterdir() if p.is_dir()), key=lambda p: int(p.name[3:]))
    _header()
    previous: tuple[FloorPlan, npt.NDArray[np.bool_]] | None = None
    shares, updates = [], []
    for folder in steps:
        grey = _grey(folder / "map.png")
        occ, _, _ = read_map(folder / "map.png", resolution_m=RES)
        free = grey >= FREE_GREY
        start, angle = None, None
        if previous is not None:
            dr, dc = align_offset(previous[1], free)  # image rows/cols of the new map = old + offset
            h = occ.shape[0]
            old_h = previous[1].shape[0]
            # GridLayer rows count from the bottom: an image shift of dr rows is a layer shift of
            # (h - old_h) - dr rows; the new map's origin lies that many cells below and left of the old one's
            lr = (h - old_h) - dr
            old = previous[0].frame
            angle = old.angle_rad
            new = make_frame(occ.shape, angle_rad=angle, origin_xy_m=(-dc * RES, -lr * RES), resolution_m=RES)
            carried = carry(previous[0].world, old, new)
            start = World(carried.units, set(), carried.next_id)
        warm = run if start is None else run._replace(iterations=warm_iterations)
        plan, seconds, cpu = _plan(occ, warm, start, angle)
        unscored = (float("nan"), float("nan"))
        r = _result(plan, rose2_occupancy(grey), unscored, unscored, seconds, cpu)
        _row("partial", folder.name, plan, r)
        if start is not None:
            updates.append(cpu)
            kept = sum(1 for u in plan.units if u.id in start.units)
            shares.append(kept / max(len(start.units), 1))
            print(f"| partial_ids | {folder.name} | kept {kept} of {len(start.units)} | | | | | | | | | | | | | |")
        previous = (plan, free)
    if shares:
        print(f"partial_ids_kept_mean {100 * statistics.fmean(shares):.2f} %")
        print(f"partial_warm_update_cpu_seconds_median {statistics.median(updates):.2f} s")


def _metres_or_none(text: str) -> float | None:
    return None if text.lower() == "none" else float(text)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--sets", nargs="*", default=["rose2", "ipa", "partial"], choices=["rose2", "ipa", "partial"])
    parser.add_argument("--iterations", type=int, default=20000)
    parser.add_argument("--warm-iterations", type=int, default=2000, help="iterations of each warm update (partial)")
    parser.add_argument("--maps", nargs="*", default=None, help="only these map names")
    parser.add_argument("--variants", nargs="*", default=[""], help="ipa suffixes, '' = plain, e.g. _furnitures")
    parser.add_argument("--seeds", nargs="+", type=int, default=[0],
                        help="chain seeds (rose2, ipa; partial: the first)")
    parser.add_argument("--trace-max-m", type=_metres_or_none, default=FloorPlanSettings().trace_max_m,
                        help="FloorPlanSettings.trace_max_m: a number of metres or 'none' (default: the setting's)")
    parser.add_argument("--restarts", type=int, default=ChainSettings().restarts,
                        help="ChainSettings.restarts: independent chains of a cold start (default: the setting's)")
    args = parser.parse_args()
    run = Run(args.iterations, args.seeds[0], args.trace_max_m, args.restarts)
    print(f"trace_max_m {args.trace_max_m}, seeds {' '.join(map(str, args.seeds))}, restarts {args.restarts}")
    if not MAPS.is_dir():
        print(f"skipped: {MAPS} is absent")
        return
    print(f"load average at start {os.getloadavg()[0]:.2f}")
    with threadpool_limits(1):
        if "rose2" in args.sets:
            _rose2(run, args.maps, args.seeds)
        if "ipa" in args.sets:
            _ipa(run, args.maps, args.variants, args.seeds)
        if "partial" in args.sets:
            _partial(run, args.warm_iterations)
    print(f"load average at end {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
