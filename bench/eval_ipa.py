"""Room segmentation on real maps, scored with the ipa protocol: every set in one command.

Sets (``--sets``, all by default):

* ``ipa``: the ipa maps read as ``aisle decompose MAP.png --resolution 0.05`` reads them
  (map_server's trinary thresholds) and scored exactly as ipa's ``evaluation_segmentation.cpp``:
  every labelled pixel of the segmentation counts, so a segment's pixels on walls lower its
  precision. The plain maps and each furnished variant (``--variants``).
* ``rose2``: the ROSE\u00b2 full maps (real robot maps, 0.05 m/px, free = grey >= 250, dark =
  occupied, the rest unknown), each ground-truth colour one room, scored on pixels free in the
  map only (both sides); ROSE\u00b2's own ``rose2_rooms.png`` scored the same way beside ours.
* ``partial``: the 15 steps of one growing ubremen map, scored like ``rose2``, plus the share of
  region ids kept from step k to k+1 where the room still exists. Each step is decomposed with the
  previous one as its prior and keyed exactly as the live decomposition worker does it
  (:func:`~services.grid_decomposition.keys.region_prior`,
  :func:`~services.grid_decomposition.keys.carry_keys`).

Prints a Markdown table per set and ``name value unit`` summary lines. Run (one BLAS thread):
``PYTHONPATH=. .venv/bin/python bench/eval_ipa.py [--sets ipa rose2 partial] [--variants '' _furnitures]``.
``--explain DIR`` adds, per ROSE² full map and partial step, what its scores are made of: per ground-truth room the
segment holding most of it, its recall and best IoU; per segment its purity (its precision term);
and ``DIR/<map>_explain.png``: the rooms coloured by their best IoU over the segments coloured by
their purity (red 0, green 1; white borders, room and segment numbers).
"""

from __future__ import annotations

import argparse
import os
import statistics
import time
from pathlib import Path
from typing import Any, NamedTuple

import cv2
import numpy as np
import numpy.typing as npt
from PIL import Image
from threadpoolctl import threadpool_limits

from services.grid_decomposition import IpaScores, decompose, ground_truth_rooms, ipa_scores
from services.grid_decomposition.evaluation import (
    FREE_GREY,
    align_offset,
    colour_rooms,
    id_stability,
    matches,
    on_free,
    shift_into,
)
from services.grid_decomposition.keys import NEXT_ID_KEY, carry_keys, region_prior
from services.grid_decomposition.mapfile import read_map_file
from services.grid_decomposition.records import decomposition_layers
from shared.store import GridLayer

MAPS = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "maps"
IPA = MAPS / "ipa_room_segmentation"
ROSE2 = MAPS / "rose2"
RESOLUTION_M = 0.05
VARIANTS = ("", "_furnitures", "_trashbins", "_furnitures_trashbins")
SETS = ("ipa", "rose2", "partial")
OCCUPIED_GREY = 89  # map_server: darkness above 0.65 is occupied
WHITE = ((0, 0, 0), (255, 255, 255))


class Row(NamedTuple):
    scores: IpaScores
    seconds: float
    cpu: float


def _grey(path: Path) -> npt.NDArray[np.uint8]:
    with Image.open(path) as image:
        return np.asarray(image.convert("L"))


def _rgb(path: Path) -> npt.NDArray[np.uint8]:
    with Image.open(path) as image:
        return np.asarray(image.convert("RGB"))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--sets", nargs="*", default=list(SETS), choices=SETS, help="which sets to run")
    parser.add_argument("--variants", nargs="*", default=list(VARIANTS), help="ipa suffixes, '' = plain")
    parser.add_argument("--maps", nargs="*", default=None, help="only these ROSE2 full maps / ipa map names")
    parser.add_argument("--explain", type=Path, default=None, help="per room / segment tables and pictures here")
    args = parser.parse_args()
    print(f"load average at start {os.getloadavg()[0]:.2f}")
    with threadpool_limits(1):
        if "ipa" in args.sets:
            _ipa(args.variants, args.maps)
        if "rose2" in args.sets:
            _rose2_full(args.maps, args.explain)
        if "partial" in args.sets:
            _partial(args.explain)
    print(f"load average at end {os.getloadavg()[0]:.2f}")


def _header(first: str) -> None:
    print(
        f"\n| {first} | map | recall % | precision % | recall_w % | precision_w % | mean IoU | rooms | segments "
        "| s | CPU s |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|---|")


def _row(tag: str, name: str, s: IpaScores, seconds: float = float("nan"), cpu: float = float("nan")) -> None:
    print(
        f"| {tag} | {name} | {100 * s.recall:.1f} | {100 * s.precision:.1f} | {100 * s.recall_weighted:.1f} | "
        f"{100 * s.precision_weighted:.1f} | {s.mean_iou:.3f} | {s.n_rooms} | {s.n_segments} | "
        f"{seconds:.2f} | {cpu:.2f} |"
    )


def _summary(tag: str, rows: list[Row]) -> None:
    """The mean row of a table and its ``name value unit`` lines."""
    if not rows:
        return
    recall = 100 * statistics.fmean(r.scores.recall for r in rows)
    precision = 100 * statistics.fmean(r.scores.precision for r in rows)
    iou = statistics.fmean(r.scores.mean_iou for r in rows)
    worst = 100 * min(r.scores.precision for r in rows)
    collapsed = sum(1 for r in rows if r.scores.n_segments <= 1)
    median_cpu = statistics.median(r.cpu for r in rows)
    print(
        f"| {tag} | **mean of {len(rows)}** | **{recall:.1f}** | **{precision:.1f}** | "
        f"{100 * statistics.fmean(r.scores.recall_weighted for r in rows):.1f} | "
        f"{100 * statistics.fmean(r.scores.precision_weighted for r in rows):.1f} | **{iou:.3f}** | | "
        f"{collapsed} collapsed | median {statistics.median(r.seconds for r in rows):.2f} | "
        f"median {median_cpu:.2f} |"
    )
    print(f"{tag}_recall {recall:.2f} %")
    print(f"{tag}_precision {precision:.2f} %")
    print(f"{tag}_mean_iou {iou:.4f} ratio")
    print(f"{tag}_worst_precision {worst:.2f} %")
    print(f"{tag}_collapsed_maps {collapsed} count")
    print(f"{tag}_median_cpu_seconds {median_cpu:.3f} s")
    print(f"{tag}_max_cpu_seconds {max(r.cpu for r in rows):.3f} s")


def _timed(occupancy: npt.NDArray[np.int8]) -> tuple[npt.NDArray[np.int32], float, float]:
    """Segments (image row order) of a decomposition, wall and CPU seconds."""
    start, cpu_start = time.perf_counter(), time.process_time()
    result = decompose(occupancy, resolution_m=RESOLUTION_M)
    seconds, cpu = time.perf_counter() - start, time.process_time() - cpu_start
    return np.ascontiguousarray(result.segments[::-1]), seconds, cpu


def _ipa(variants: list[str], only: list[str] | None) -> None:
    names = sorted(p.name[: -len("_gt_segmentation.png")] for p in IPA.glob("*_gt_segmentation.png"))
    if only:
        names = [n for n in names if n in only]
    _header("variant")
    for variant in variants:
        tag = f"ipa_{variant.strip('_') or 'plain'}"
        rows: list[Row] = []
        for name in names:
            path = IPA / f"{name}{variant}.png"
            if not path.exists():
                continue
            truth = _grey(IPA / f"{name}_gt_segmentation.png")
            occupancy, _, _ = read_map_file(path, resolution_m=RESOLUTION_M)
            if occupancy.shape != truth.shape:
                print(f"| {tag} | {name} | skipped: map {occupancy.shape} != ground truth {truth.shape} |")
                continue
            segments, seconds, cpu = _timed(occupancy)
            s = ipa_scores(segments, ground_truth_rooms(truth))
            rows.append(Row(s, seconds, cpu))
            _row(tag, name, s, seconds, cpu)
        _summary(tag, rows)


def rose2_occupancy(grey: npt.NDArray[np.uint8]) -> npt.NDArray[np.int8]:
    """Occupancy (GridLayer order) of a ROSE\u00b2 map: >= 250 free, <= 89 occupied, the rest unknown."""
    occ = np.full(grey.shape, -1, dtype=np.int8)
    occ[grey >= FREE_GREY] = 0
    occ[grey <= OCCUPIED_GREY] = 100
    return occ[::-1].copy()


def _common(*images: npt.NDArray[Any]) -> list[npt.NDArray[Any]]:
    """Images cut to their common top-left part (one ROSE2 ground truth is a row shorter than its map)."""
    h = min(i.shape[0] for i in images)
    w = min(i.shape[1] for i in images)
    return [i[:h, :w] for i in images]


def _rose2_map(folder: Path) -> tuple[npt.NDArray[np.int32], npt.NDArray[np.bool_], IpaScores, IpaScores, Row]:
    """Our segments, the free mask, our scores, ROSE2's scores and our row for one map folder."""
    grey = _grey(folder / "map.png")
    segments, seconds, cpu = _timed(rose2_occupancy(grey))
    ours, s, peer, free = _rose2_scores(folder, grey, segments)
    return ours, free, s, peer, Row(s, seconds, cpu)


def _rose2_scores(
    folder: Path, grey: npt.NDArray[np.uint8], segments: npt.NDArray[np.int32]
) -> tuple[npt.NDArray[np.int32], IpaScores, IpaScores, npt.NDArray[np.bool_]]:
    """Our segments (image order) and the free mask cut to the ground truth, our scores and ROSE2's."""
    grey, gt, theirs, ours = _common(grey, _rgb(folder / "gt.png"), _rgb(folder / "rose2_rooms.png"), segments)
    free = grey >= FREE_GREY
    rooms = on_free(colour_rooms(gt), free)
    s = ipa_scores(on_free(ours, free), rooms)
    peer = ipa_scores(on_free(colour_rooms(theirs, background=WHITE), free), rooms)
    return np.asarray(ours, dtype=np.int32), s, peer, free


def _rose2_full(only: list[str] | None, explain: Path | None = None) -> None:
    _header("set")
    ours: list[Row] = []
    theirs: list[Row] = []
    for folder in sorted(p for p in (ROSE2 / "full").iterdir() if p.is_dir()):
        if only and folder.name not in only:
            continue
        segments, free, s, peer, row = _rose2_map(folder)
        if explain is not None:
            _explain(folder, segments, free, explain)
        ours.append(row)
        theirs.append(Row(peer, float("nan"), float("nan")))
        _row("rose2", folder.name, s, row.seconds, row.cpu)
        _row("rose2_peer", folder.name, peer)
    _summary("rose2", ours)
    _summary("rose2_peer", theirs)


def _explain(folder: Path, segments: npt.NDArray[np.int32], free: npt.NDArray[np.bool_], out: Path) -> None:
    """Print what one map's scores are made of and draw it (see the module docstring)."""
    rooms = on_free(colour_rooms(_common(_rgb(folder / "gt.png"), free)[0]), free)
    ours = on_free(segments, free)
    room_rows, segment_rows = matches(ours, rooms)
    print(f"\n{folder.name}: room, m\u00b2, segment holding most of it, recall, best IoU")
    for r in room_rows:
        print(f"  R{r.room} {r.pixels * RESOLUTION_M**2:.1f} {r.segment} {r.recall:.2f} {r.iou:.2f}")
    print(f"{folder.name}: segment, m\u00b2, room holding most of it, purity")
    for g in segment_rows:
        print(f"  {g.segment} {g.pixels * RESOLUTION_M**2:.1f} R{g.room} {g.purity:.2f}")
    top, bottom = (np.repeat(np.where(free, 90, 170).astype(np.uint8)[..., None], 3, axis=2) for _ in range(2))
    iou = np.zeros(int(rooms.max()) + 1)
    iou[[r.room for r in room_rows]] = [r.iou for r in room_rows]
    purity = np.zeros(int(ours.max()) + 1)
    purity[[g.segment for g in segment_rows]] = [g.purity for g in segment_rows]
    scored = np.isin(ours, [g.segment for g in segment_rows])
    for image, labels, value, mask in ((top, rooms, iou, rooms > 0), (bottom, ours, purity, scored)):
        v = value[labels][mask]
        image[mask] = np.stack([255 * (1 - v), 255 * v, np.zeros_like(v)], axis=1).astype(np.uint8)
        image[_borders(labels)] = 255
        for k in np.unique(labels[mask]).tolist():
            rows, cols = np.nonzero(labels == k)
            cv2.putText(image, f"R{k}" if labels is rooms else str(k), (int(cols.mean()), int(rows.mean())),
                        cv2.FONT_HERSHEY_SIMPLEX, 0.45, (255, 255, 255), 1)
    rows, cols = np.nonzero(free)
    crop = (slice(max(int(rows.min()) - 20, 0), int(rows.max()) + 21),
            slice(max(int(cols.min()) - 20, 0), int(cols.max()) + 21))
    picture = np.vstack([top[crop], np.full((8, top[crop].shape[1], 3), 255, np.uint8), bottom[crop]])
    out.mkdir(parents=True, exist_ok=True)
    Image.fromarray(picture).save(out / f"{folder.name}_explain.png")


def _borders(labels: npt.NDArray[np.int32]) -> npt.NDArray[np.bool_]:
    edge = np.zeros(labels.shape, dtype=bool)
    edge[1:] |= labels[1:] != labels[:-1]
    edge[:, 1:] |= labels[:, 1:] != labels[:, :-1]
    return edge


def _partial(explain: Path | None = None) -> None:
    """Each step decomposed and keyed as the live worker does it: the steps are placed in one map frame (the FFT
    alignment of their free masks gives each grid's origin), the previous step's segment layer and occupancy
    are the prior (:func:`~services.grid_decomposition.keys.region_prior`) and the keys are carried
    (:func:`~services.grid_decomposition.keys.carry_keys`)."""
    steps = sorted(
        (p for p in (ROSE2 / "partial_ubremen").iterdir() if p.is_dir()), key=lambda p: int(p.name[3:])
    )
    _header("step")
    ours: list[Row] = []
    theirs: list[Row] = []
    shares: list[float] = []
    previous: tuple[GridLayer, GridLayer, npt.NDArray[np.int32], npt.NDArray[np.bool_]] | None = None
    corner = np.zeros(2, dtype=np.int64)  # (y, x) cells of this step's lower-left corner in the first step's frame
    for folder in steps:
        grey = _grey(folder / "map.png")
        free_px = grey >= FREE_GREY
        if previous is not None:
            offset = align_offset(previous[3], free_px)  # the previous image's top-left corner in this one
            corner += [grey.shape[0] - offset[0] - previous[3].shape[0], offset[1]]  # its lower-left, here
        occupancy = GridLayer("occupancy", rose2_occupancy(grey), RESOLUTION_M, float(-corner[1] * RESOLUTION_M),
                              float(-corner[0] * RESOLUTION_M))
        origin = (occupancy.origin_x_m, occupancy.origin_y_m)
        start, cpu_start = time.perf_counter(), time.process_time()
        prior = None if previous is None else region_prior(previous[0], previous[1], occupancy)
        result, ids = carry_keys(decompose(occupancy.data, resolution_m=RESOLUTION_M, origin_xy_m=origin,
                                           prior=prior), None if previous is None else previous[0])
        seconds, cpu = time.perf_counter() - start, time.process_time() - cpu_start
        segments, s, peer, free = _rose2_scores(folder, grey, np.ascontiguousarray(result.segments[::-1]))
        if explain is not None:
            _explain(folder, segments, free, explain)
        row = Row(s, seconds, cpu)
        step = int(folder.name[3:])
        _row("partial", folder.name, s, row.seconds, row.cpu)
        _row("partial_peer", folder.name, peer)
        if step >= 5:
            ours.append(row)
            theirs.append(Row(peer, float("nan"), float("nan")))
        segments = on_free(segments, free)
        if previous is not None:
            moved = shift_into(previous[2], offset, segments.shape)
            rooms = on_free(colour_rooms(_common(_rgb(folder / "gt.png"), segments)[0]), free)
            kept = id_stability(moved, segments, rooms)
            shares.append(kept.share)
            print(f"| partial_ids | {folder.name} | kept {kept.kept} of {kept.matched} ({100 * kept.share:.0f} %) "
                  f"| offset {offset} | | | | | | | |")
        layer = decomposition_layers(result, meta={NEXT_ID_KEY: ids.next_id})[1]
        previous = (layer, occupancy, segments, free_px)
    _summary("partial_from_step5", ours)
    _summary("partial_peer_from_step5", theirs)
    if shares:
        print(f"partial_ids_kept_mean {100 * statistics.fmean(shares):.2f} %")
        print(f"partial_ids_kept_worst {100 * min(shares):.2f} %")


if __name__ == "__main__":
    main()
