"""The load-scene stage's whole path on rendered data: depth frames -> boxes -> scene graphs -> fused bin states in
a SQLite store -> WMS stock discrepancies, against the simulator's ground truth; and the CPU it takes per frame.

Seeded loaded halls (:func:`services.simulator.loads.loaded_layout`, single- and double-deep, 2 aisles of 6 bays,
3 levels). A robot with a mast of two rack-facing RGB-D cameras (:data:`~services.simulator.loads.RACK_CAMERAS`)
drives down every aisle past each rack face, ``--passes`` times (each pass its own depth noise): at every bay it
takes frames at ``--along`` offsets along the face (the frames a robot driving by takes there). The frames of one
bay stop are one commit of the worker (:class:`services.load_scenes.worker.LoadScenesStage` does the same per
``commit_period_s``): for each bay in view its views' estimates are merged, the scene graph inferred, the bins'
occupancy read off and fused with their earlier state, and the changed states and scenes written as one revision
(:class:`shared.loads.SceneWriter`). After the drive the WMS stock list (every bin, every ``--error-every``-th
booked wrongly) is imported and :func:`atlas.stock.stock_discrepancies` (``min_views`` 2) asked.

Figures:

- occupancy right, of bins decided (``empty``/``occupied``): the target is >= 99.5 % of bins seen from the aisle;
  bins left ``unknown`` (not seen, or seen only in part and empty there) are counted apart;
- planted discrepancies reported, of those on bins seen >= 2 times; false discrepancies on such bins;
- CPU time (``time.process_time``, one BLAS thread) per frame of each step: estimation (per frame), inference +
  occupancy (per bay per commit), writing (per commit), and the whole path per frame; frames/s per core against
  3 RGB-D robots at 15 fps (45 frames/s).

    PYTHONPATH=. .venv/bin/python bench/bench_load_scenes_pipeline.py [--seeds 1 2 3] [--passes 2]

Prints ``name value unit`` lines.
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from collections import defaultdict
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np
from threadpoolctl import threadpool_limits

from atlas.cache import RevisionCache
from atlas.stock import import_wms_stock, stock_discrepancies
from services.load_scenes.estimation import RackView, bays_from_bins, estimate_boxes, merge_views
from services.load_scenes.frames import Intrinsics
from services.load_scenes.inference import infer_scene
from services.load_scenes.model import Bay, BinOccupancy, Occupancy, SceneGraph
from services.load_scenes.occupancy import OccupancySettings, bin_evidence, bin_occupancy, fuse_occupancy
from services.simulator import RgbdModel, depth_image_mm, render_boxes, world_from_layout
from services.simulator.loads import RACK_CAMERAS, bin_records, loaded_layout, rack_view
from shared.loads import SceneWriter
from shared.store import MapStore, RevisionWrite, WmsStock
from shared.vocabulary import FeatureKind


class Clock:
    """CPU seconds and calls per step."""

    def __init__(self) -> None:
        self.cpu: dict[str, float] = defaultdict(float)
        self.calls: dict[str, int] = defaultdict(int)

    @contextmanager
    def step(self, name: str) -> Iterator[None]:
        start = time.process_time()
        yield
        self.cpu[name] += time.process_time() - start
        self.calls[name] += 1


def _commit(views: dict[str, list[RackView]], bays: dict[str, Bay], states: dict[str, BinOccupancy],
            writer: SceneWriter, clock: Clock) -> None:
    """What the worker does at a commit: explain each bay seen, fuse its bins, write one revision."""
    scenes: list[SceneGraph] = []
    changed: list[BinOccupancy] = []
    for key, seen in sorted(views.items()):
        bay = bays[key]
        with clock.step("inference"):
            estimates = merge_views([b for view in seen for b in view.boxes if b.bay == key])
            evidence = [view.evidence[key] for view in seen]
            graph = infer_scene(bay, estimates, evidence)
            occupancy = bin_occupancy(bay, graph, bin_evidence(bay, graph, evidence))
        scenes.append(graph)
        for state in occupancy:
            states[state.bin_id] = fuse_occupancy(states.get(state.bin_id), state)
            changed.append(states[state.bin_id])
    with clock.step("write"):
        writer.write(scenes, changed)


def _why_unknown(state: BinOccupancy | None, bays: dict[str, Bay], bin_id: str) -> str:
    """Why a bin is unknown: its level (``level<i>``) and no rays through it / seen in part only / undecided."""
    bay = next(bay for bay in bays.values() if bin_id in bay.bin_ids)
    level = bay.bin_ids.index(bin_id)
    rays = 0 if state is None else state.detail.get("rays", 0)
    covered = 0.0 if state is None else state.detail.get("covered", 1.0)
    if not isinstance(rays, int) or rays < 15:
        reason = "no_rays"
    elif isinstance(covered, float) and (1.0 - covered) * bay.width_m > OccupancySettings().max_uncovered_m:
        reason = "seen_in_part"
    else:
        reason = "undecided"
    return f"level{level}_{reason}"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3])
    parser.add_argument("--passes", type=int, default=2)
    parser.add_argument("--along", type=float, nargs="+", default=[-0.9, 0.0, 0.9])
    parser.add_argument("--standoff-m", type=float, default=2.8)
    parser.add_argument("--error-every", type=int, default=7)
    args = parser.parse_args()
    model = RgbdModel()
    camera = model.camera()
    intrinsics = Intrinsics(camera.fx, camera.fy, camera.cx, camera.cy, camera.width, camera.height)
    clock = Clock()
    frames = commits = 0
    decided = right = unknown = total_bins = 0
    planted = found = false = well_seen = 0
    wrong: list[str] = []
    why_unknown: dict[str, int] = defaultdict(int)
    for seed in args.seeds:
        for deep in (1, 2):
            world = world_from_layout(loaded_layout(seed, deep=deep))
            records = bin_records(world)
            bays = {bay.key: bay for bay in bays_from_bins(records)}
            truth = {b.id: b.occupied for b in world.bins}
            rng = np.random.default_rng(seed * 10 + deep)
            states: dict[str, BinOccupancy] = {}
            with tempfile.TemporaryDirectory() as tmp, threadpool_limits(1):
                store = MapStore(f"sqlite:///{Path(tmp) / 'bench.db'}")
                store.upgrade()
                info = store.ensure_map("hall")
                store.write_revision(info.id, RevisionWrite("pillar_mapping",
                                                            features={FeatureKind.BIN: [b.feature() for b in records]}))
                writer = SceneWriter(store, info.id)
                for _ in range(args.passes):
                    for bay in bays.values():
                        views: dict[str, list[RackView]] = defaultdict(list)
                        for along in args.along:
                            for height, pitch in RACK_CAMERAS:
                                pose = rack_view(world, bay.bin_ids[0], standoff_m=args.standoff_m, height_m=height,
                                                 pitch_up_rad=pitch, along_m=along)
                                depth = depth_image_mm(render_boxes(world.boxes, pose, camera, far_m=8.0).depth_m,
                                                       model, rng)
                                with clock.step("estimation"):
                                    view = estimate_boxes(depth, intrinsics, pose, list(bays.values()),
                                                          stamp_ns=frames)
                                frames += 1
                                for key in view.evidence:
                                    views[key].append(view)
                        _commit(views, bays, states, writer, clock)
                        commits += 1
                for bin_id, occupied in truth.items():
                    total_bins += 1
                    state = states.get(bin_id)
                    if state is None or state.state is Occupancy.UNKNOWN:
                        unknown += 1
                        why_unknown[_why_unknown(state, bays, bin_id)] += 1
                        continue
                    decided += 1
                    if (state.state is Occupancy.OCCUPIED) == occupied:
                        right += 1
                    else:
                        wrong.append(f"{seed}/{deep}/{bin_id}:{state.state.value}:{state.confidence:.2f}:"
                                     f"{state.views}:{state.detail}")
                ids = sorted(truth)
                errors = set(ids[::args.error_every])
                stock = [WmsStock(b, holds_stock=truth[b] != (b in errors)) for b in ids]
                import_wms_stock(store, info.id, stock, complete=False)
                check = stock_discrepancies(store, RevisionCache(), info, revision=None, min_views=2)
                reported = {d.detected_id for d in check.discrepancies}
                seen2 = {k for k, s in states.items() if s.state is not Occupancy.UNKNOWN and s.views >= 2}
                well_seen += len(seen2)
                planted += len(errors & seen2)
                found += len(errors & seen2 & reported)
                false += len(reported - errors)
                store.close()
    print(f"seeds {len(args.seeds)} count")
    print(f"frames {frames} count")
    print(f"commits {commits} count")
    print(f"bins {total_bins} count")
    print(f"bins_decided {decided} count")
    print(f"bins_unknown {unknown} count")
    for why, count in sorted(why_unknown.items()):
        print(f"bins_unknown_{why} {count} count")
    print(f"occupancy_right_of_decided {100.0 * right / max(decided, 1):.2f} %")
    for line in wrong:
        print(f"# wrong {line}")
    print(f"bins_seen_twice {well_seen} count")
    print(f"planted_discrepancies_on_bins_seen_twice {planted} count")
    print(f"planted_discrepancies_reported {found} count")
    print(f"false_discrepancies {false} count")
    est_ms = 1000.0 * clock.cpu["estimation"] / max(clock.calls["estimation"], 1)
    inf_ms = 1000.0 * clock.cpu["inference"] / max(clock.calls["inference"], 1)
    write_ms = 1000.0 * clock.cpu["write"] / max(clock.calls["write"], 1)
    total = sum(clock.cpu.values())
    print(f"cpu_ms_estimation_per_frame {est_ms:.2f} ms")
    print(f"cpu_ms_inference_per_bay_commit {inf_ms:.2f} ms")
    print(f"bays_per_commit {clock.calls['inference'] / max(commits, 1):.2f} count")
    print(f"cpu_ms_write_per_commit {write_ms:.2f} ms")
    print(f"cpu_ms_whole_path_per_frame {1000.0 * total / max(frames, 1):.2f} ms")
    print(f"frames_per_s_per_core_whole_path {frames / total:.1f} 1/s")
    print(f"frames_per_s_per_core_estimation_only {1000.0 / est_ms:.1f} 1/s")
    print(f"loadavg_1min {os.getloadavg()[0]:.2f} load")


if __name__ == "__main__":
    main()
