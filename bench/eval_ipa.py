"""Room segmentation on the ipa maps with the ipa protocol: per-map table and averages.

Prints one row per map (recall, precision, weighted forms, mean best IoU, rooms, segments,
wall and CPU seconds) for the plain maps and for each furnished variant, then ``name value unit``
summary lines. Room segments include the furniture standing in them (the ground truth rooms do);
the column "recall free %" scores the same segments cut back to free pixels. Run:
``PYTHONPATH=. .venv/bin/python bench/eval_ipa.py`` (the table is Markdown; one BLAS thread).
"""

from __future__ import annotations

import argparse
import os
import statistics
import time
from pathlib import Path

import numpy as np
from PIL import Image
from threadpoolctl import threadpool_limits

from services.grid_decomposition import IpaScores, decompose, ground_truth_rooms, ipa_scores
from services.grid_decomposition.evaluation import FREE_GREY

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "maps" / "ipa_room_segmentation"
RESOLUTION_M = 0.05
VARIANTS = ("", "_furnitures", "_trashbins", "_furnitures_trashbins")


def _grey(path: Path) -> np.ndarray:
    with Image.open(path) as image:
        return np.asarray(image.convert("L"))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--variants", nargs="*", default=list(VARIANTS), help="suffixes, '' = plain")
    variants = parser.parse_args().variants
    names = sorted(p.name[: -len("_gt_segmentation.png")] for p in DATA.glob("*_gt_segmentation.png"))
    print(f"load average at start {os.getloadavg()[0]:.2f}")
    print(
        "| variant | map | recall % | precision % | recall_w % | precision_w % | mean IoU | recall free % "
        "| rooms | segments | s | CPU s |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    with threadpool_limits(1):
        for variant in variants:
            _variant(variant, names)
    print(f"load average at end {os.getloadavg()[0]:.2f}")


def _variant(variant: str, names: list[str]) -> None:
    """Rows of one variant, its mean row and its ``name value unit`` summary lines."""
    tag = variant.strip("_") or "plain"
    rows: list[tuple[IpaScores, IpaScores, float, float]] = []
    for name in names:
        path = DATA / f"{name}{variant}.png"
        if not path.exists():
            continue
        grey = _grey(path)
        truth = _grey(DATA / f"{name}_gt_segmentation.png")
        if grey.shape != truth.shape:
            print(f"| {tag} | {name} | skipped: map {grey.shape} != ground truth {truth.shape} |")
            continue
        occupancy = np.where(grey >= FREE_GREY, 0, 100).astype(np.int8)[::-1].copy()
        start, cpu_start = time.perf_counter(), time.process_time()
        result = decompose(occupancy, resolution_m=RESOLUTION_M)
        seconds, cpu = time.perf_counter() - start, time.process_time() - cpu_start
        rooms = ground_truth_rooms(truth)
        segments = result.segments[::-1]
        s = ipa_scores(segments, rooms)
        on_free = ipa_scores(np.where(grey >= FREE_GREY, segments, 0), rooms)
        rows.append((s, on_free, seconds, cpu))
        print(
            f"| {tag} | {name} | {100 * s.recall:.1f} | {100 * s.precision:.1f} | "
            f"{100 * s.recall_weighted:.1f} | {100 * s.precision_weighted:.1f} | {s.mean_iou:.3f} | "
            f"{100 * on_free.recall:.1f} | {s.n_rooms} | {s.n_segments} | {seconds:.2f} | {cpu:.2f} |"
        )
    if not rows:
        return
    recall = 100 * statistics.fmean(r[0].recall for r in rows)
    precision = 100 * statistics.fmean(r[0].precision for r in rows)
    iou = statistics.fmean(r[0].mean_iou for r in rows)
    recall_free = 100 * statistics.fmean(r[1].recall for r in rows)
    median_s = statistics.median(r[2] for r in rows)
    median_cpu = statistics.median(r[3] for r in rows)
    collapsed = sum(1 for r in rows if r[0].n_segments <= 1)
    print(
        f"| {tag} | **mean of {len(rows)}** | **{recall:.1f}** | **{precision:.1f}** | "
        f"{100 * statistics.fmean(r[0].recall_weighted for r in rows):.1f} | "
        f"{100 * statistics.fmean(r[0].precision_weighted for r in rows):.1f} | **{iou:.3f}** | {recall_free:.1f} "
        f"| | {collapsed} collapsed | median {median_s:.2f} | median {median_cpu:.2f} |"
    )
    print(f"ipa_{tag}_recall {recall:.2f} %")
    print(f"ipa_{tag}_precision {precision:.2f} %")
    print(f"ipa_{tag}_mean_iou {iou:.4f} ratio")
    print(f"ipa_{tag}_recall_free_pixels {recall_free:.2f} %")
    print(f"ipa_{tag}_collapsed_maps {collapsed} count")
    print(f"ipa_{tag}_median_seconds {median_s:.3f} s")
    print(f"ipa_{tag}_median_cpu_seconds {median_cpu:.3f} s")


if __name__ == "__main__":
    main()
