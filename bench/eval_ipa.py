"""Room segmentation on the ipa maps with the ipa protocol: per-map table and averages.

Prints one row per map (recall, precision, weighted forms, mean best IoU, rooms, segments,
seconds) for the plain maps and for each furnished variant, then ``name value unit`` summary
lines. Run: ``.venv/bin/python bench/eval_ipa.py`` (the table is Markdown).
"""

from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

import numpy as np
from PIL import Image

from services.grid_decomposition import decompose, ground_truth_rooms, ipa_scores
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
    print("| variant | map | recall % | precision % | recall_w % | precision_w % | mean IoU | rooms | segments | s |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for variant in variants:
        rows = []
        for name in names:
            path = DATA / f"{name}{variant}.png"
            if not path.exists():
                continue
            grey = _grey(path)
            truth = _grey(DATA / f"{name}_gt_segmentation.png")
            if grey.shape != truth.shape:
                print(f"| {variant or 'plain'} | {name} | skipped: map {grey.shape} != ground truth {truth.shape} |")
                continue
            occupancy = np.where(grey >= FREE_GREY, 0, 100).astype(np.int8)[::-1].copy()
            start = time.perf_counter()
            result = decompose(occupancy, resolution_m=RESOLUTION_M)
            seconds = time.perf_counter() - start
            rooms = ground_truth_rooms(truth)
            s = ipa_scores(result.segments[::-1], rooms)
            rows.append((s, seconds))
            print(
                f"| {variant or 'plain'} | {name} | {100 * s.recall:.1f} | {100 * s.precision:.1f} | "
                f"{100 * s.recall_weighted:.1f} | {100 * s.precision_weighted:.1f} | {s.mean_iou:.3f} | "
                f"{s.n_rooms} | {s.n_segments} | {seconds:.2f} |"
            )
        if not rows:
            continue
        tag = variant.strip("_") or "plain"
        mean = {
            "recall": 100 * statistics.fmean(r.recall for r, _ in rows),
            "precision": 100 * statistics.fmean(r.precision for r, _ in rows),
            "iou": statistics.fmean(r.mean_iou for r, _ in rows),
        }
        print(
            f"| {tag} | **mean of {len(rows)}** | **{mean['recall']:.1f}** | **{mean['precision']:.1f}** | "
            f"{100 * statistics.fmean(r.recall_weighted for r, _ in rows):.1f} | "
            f"{100 * statistics.fmean(r.precision_weighted for r, _ in rows):.1f} | **{mean['iou']:.3f}** | | "
            f"{sum(1 for r, _ in rows if r.n_segments <= 1)} collapsed | "
            f"median {statistics.median(t for _, t in rows):.2f} |"
        )
        print(f"ipa_{tag}_recall {mean['recall']:.2f} %")
        print(f"ipa_{tag}_precision {mean['precision']:.2f} %")
        print(f"ipa_{tag}_mean_iou {mean['iou']:.4f} ratio")
        print(f"ipa_{tag}_median_seconds {statistics.median(t for _, t in rows):.3f} s")


if __name__ == "__main__":
    main()
