"""Object-labelling segmentation on simulated RGB-D frames: the share of objects in view it finds.

Renders ``--views`` views of scatter halls seeded from ``--first-hall`` (20 views each; halls
1000+ train the classifier, 2000+ evaluate it, so the default 3000+ is unseen), runs the
range/height scan, segmentation and retrieval on each, and matches segment ROIs with the boxes of
the actors in view (at least half of the actor visible; IoU >= 0.5, one-to-one). Prints
``name value unit`` lines: recall overall and per class, segments and false proposals per frame,
median IoU of the matches, and CPU time per frame of the segmentation steps.

    PYTHONPATH=. .venv/bin/python bench/bench_object_labelling_segmentation.py [--views 400]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from services.labelling_training.matching import score_segmentation
from services.labelling_training.sim_training import simulated_views
from services.labelling_training.sim_views import SimView
from services.object_labelling import PriorDatabase
from services.simulator import photo_textures


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--views", type=int, default=400)
    parser.add_argument("--first-hall", type=int, default=3000)
    args = parser.parse_args()
    halls = range(args.first_hall, args.first_hall + -(-args.views // 20))
    start = time.process_time()
    views: list[SimView] = list(simulated_views(halls, 20, textures=photo_textures(), seed=3))[: args.views]
    render_s = time.process_time() - start
    start = time.process_time()
    score = score_segmentation(views, PriorDatabase.read_csv())
    segment_s = time.process_time() - start
    total = sum(score.objects.values())
    print(f"segmentation_views {score.views} frames")
    print(f"segmentation_objects_in_view {total} objects")
    print(f"segmentation_recall {score.recall:.3f} ratio")
    for label in sorted(score.objects):
        print(f"segmentation_recall_{label} {score.found.get(label, 0) / score.objects[label]:.3f} ratio "
              f"({score.found.get(label, 0)} of {score.objects[label]})")
    print(f"segmentation_median_iou {np.median(score.ious):.3f} ratio")
    print(f"segments_per_frame {score.segments / score.views:.2f} segments")
    print(f"false_proposals_per_frame {score.false_proposals / score.views:.2f} segments")
    print(f"render_cpu_per_frame {1000 * render_s / score.views:.0f} ms")
    print(f"scan_segments_retrieval_cpu_per_frame {1000 * segment_s / score.views:.1f} ms")


if __name__ == "__main__":
    main()
