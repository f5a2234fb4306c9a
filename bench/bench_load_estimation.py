"""Box estimation at rack faces: detection recall and precision per kind, pose errors and time per frame.

Seeded loaded halls (:func:`services.simulator.loads.loaded_layout`, single- and double-deep); a robot stops in
front of every bay and its mast's two rack-facing RGB-D cameras (:data:`~services.simulator.loads.RACK_CAMERAS`)
take one 640x480 frame each, with the simulator's depth noise. Per frame :func:`estimate_boxes` runs on the
depth image and the rack model built from the world's bins (:func:`bays_from_bins`).

- Recall: of the pallets and loads a frame shows whole (``seen_whole``: at least 60 % of the silhouette visible,
  not cut by the image border), the share with an estimate of the same kind in the right bin whose centre is
  within 0.15 m across and up and 0.4 m into the rack (a front view does not see the depth). Beams: the target
  bay's beam fronts wholly in the image.
- Precision: of the pallet and load estimates, the share matching any object (seen whole or not) so.
- Pose errors of the matched pairs: median and 95th percentile of the centre error along the bay's axes
  (across ``u``, into the rack ``v``, up ``z``) and of the width and height.
- Hidden: back pallets of double-deep bays with a pallet in front, in the image but under a quarter of their
  front face showing; an estimate matching one would be a pallet "seen" through another.
- Time: CPU time (``time.process_time``) and wall time per frame of ``estimate_boxes`` (rendering excluded),
  frames/s per core; the stage must keep up with 3 RGB-D robots at 15 fps (45 frames/s).

    PYTHONPATH=. .venv/bin/python bench/bench_load_estimation.py [--seeds 1 2 3] [--stride 2]

Prints ``name value unit`` lines.
"""

from __future__ import annotations

import argparse
import math
import os
import time
from collections import defaultdict

import numpy as np
from threadpoolctl import threadpool_limits

from services.load_scenes.estimation import bays_from_bins, estimate_boxes
from services.load_scenes.frames import Intrinsics
from services.load_scenes.model import Bay, BoxEstimate, ObjectKind
from services.simulator import RgbdModel, depth_image_mm, render_boxes, world_from_layout
from services.simulator.loads import RACK_CAMERAS, bin_records, loaded_layout, rack_view, seen_whole
from services.simulator.world import LoadTruth, ObjectClass, World

KINDS = {ObjectClass.PALLET: ObjectKind.PALLET, ObjectClass.LOAD: ObjectKind.LOAD}
TOL_UZ_M, TOL_V_M = 0.15, 0.4


def _bay_frame(bay: Bay, xy: tuple[float, float]) -> tuple[float, float]:
    dx, dy = xy[0] - bay.origin[0], xy[1] - bay.origin[1]
    c, s = math.cos(bay.yaw_rad), math.sin(bay.yaw_rad)
    return dx * s - dy * c, dx * c + dy * s


def _truth_uvz(world: World, bay: Bay, truth: LoadTruth) -> tuple[float, float, float, float, float]:
    """Centre (u, v, z), width across and height of a truth box in the bay frame."""
    i = truth.box
    u, v = _bay_frame(bay, (float(world.boxes.centre_xy[i, 0]), float(world.boxes.centre_xy[i, 1])))
    z0, z1 = world.boxes.z_m[i]
    return u, v, 0.5 * float(z0 + z1), float(world.boxes.size_xy[i, 0]), float(z1 - z0)


def _errors(world: World, bay: Bay, truth: LoadTruth, est: BoxEstimate) -> tuple[float, ...] | None:
    """(du, dv, dz, dwidth, dheight) if ``est`` matches ``truth`` (kind, bin, tolerances), else None."""
    if KINDS[truth.kind] is not est.kind or est.level is None or bay.bin_ids[est.level] != truth.bin_id:
        return None
    u, v, z, width, height = _truth_uvz(world, bay, truth)
    eu, ev = _bay_frame(bay, est.centre[:2])
    d = (eu - u, ev - v, est.centre[2] - z, est.size[0] - width, est.size[2] - height)
    return d if abs(d[0]) <= TOL_UZ_M and abs(d[2]) <= TOL_UZ_M and abs(d[1]) <= TOL_V_M else None


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3])
    parser.add_argument("--stride", type=int, default=2)
    parser.add_argument("--standoff-m", type=float, default=2.8)
    args = parser.parse_args()
    model = RgbdModel()
    camera = model.camera()
    intrinsics = Intrinsics(camera.fx, camera.fy, camera.cx, camera.cy, camera.width, camera.height)
    seen: dict[ObjectKind, int] = defaultdict(int)
    found: dict[ObjectKind, int] = defaultdict(int)
    estimated: dict[ObjectKind, int] = defaultdict(int)
    right: dict[ObjectKind, int] = defaultdict(int)
    errors: dict[ObjectKind, list[tuple[float, ...]]] = defaultdict(list)
    beam_top: list[float] = []
    hidden = hidden_hit = 0
    cpu: list[float] = []
    wall: list[float] = []
    frames = 0
    for seed in args.seeds:
        for deep in (1, 2):
            world = world_from_layout(loaded_layout(seed, deep=deep))
            bays = bays_from_bins(bin_records(world))
            by_bin = {b: bay for bay in bays for b in bay.bin_ids}
            rng = np.random.default_rng(seed)
            for bay in bays:
                for height, pitch in RACK_CAMERAS:
                    pose = rack_view(world, bay.bin_ids[0], standoff_m=args.standoff_m, height_m=height,
                                     pitch_up_rad=pitch)
                    rendered = render_boxes(world.boxes, pose, camera, far_m=8.0)
                    depth = depth_image_mm(rendered.depth_m, model, rng)
                    with threadpool_limits(1):
                        c0, w0 = time.process_time(), time.perf_counter()
                        view = estimate_boxes(depth, intrinsics, pose, bays, stamp_ns=frames, stride=args.stride)
                        cpu.append(time.process_time() - c0)
                        wall.append(time.perf_counter() - w0)
                    frames += 1
                    objects = [e for e in view.boxes if e.kind is not ObjectKind.BEAM]
                    truths = [t for t in world.loads if t.bin_id in by_bin]
                    for truth in seen_whole(world, rendered, pose, camera):
                        kind = KINDS[truth.kind]
                        seen[kind] += 1
                        matches = [d for e in objects if (d := _errors(world, by_bin[truth.bin_id], truth, e))]
                        if matches:
                            found[kind] += 1
                            errors[kind].append(min(matches, key=lambda d: abs(d[0]) + abs(d[2])))
                    for est in objects:
                        estimated[est.kind] += 1
                        if any(_errors(world, by_bin[t.bin_id], t, est) for t in truths):
                            right[est.kind] += 1
                    in_image = {t.id for t in seen_whole(world, rendered, pose, camera, min_fraction=0.0)}
                    glimpsed = {t.id for t in seen_whole(world, rendered, pose, camera, min_fraction=0.25)}
                    for truth in truths:
                        if (truth.behind and truth.kind == ObjectClass.PALLET and truth.id in in_image
                                and truth.id not in glimpsed):
                            hidden += 1
                            hidden_hit += any(_errors(world, by_bin[truth.bin_id], truth, e) for e in objects)
                    for est in view.boxes:
                        if est.kind is ObjectKind.BEAM and est.bay == bay.key and est.level is not None:
                            beam_top.append(est.centre[2] + 0.5 * est.size[2] - bay.levels_z_m[est.level])
    print(f"frames {frames} count")
    for kind in (ObjectKind.PALLET, ObjectKind.LOAD):
        print(f"{kind.value}_seen_whole {seen[kind]} count")
        print(f"{kind.value}_recall {found[kind] / max(seen[kind], 1):.4f} ratio")
        print(f"{kind.value}_precision {right[kind] / max(estimated[kind], 1):.4f} ratio")
        e = np.abs(np.array(errors[kind])).reshape(-1, 5)
        for k, name in enumerate(("u", "v", "z", "width", "height")):
            if len(e):
                print(f"{kind.value}_err_{name}_median {np.median(e[:, k]):.4f} m")
                print(f"{kind.value}_err_{name}_p95 {np.percentile(e[:, k], 95):.4f} m")
    top = np.abs(np.array(beam_top))
    print(f"beam_estimates {len(top)} count")
    if len(top):
        print(f"beam_top_err_median {np.median(top):.4f} m")
        print(f"beam_top_err_p95 {np.percentile(top, 95):.4f} m")
    print(f"hidden_back_pallets {hidden} count")
    print(f"hidden_back_pallets_estimated {hidden_hit} count")
    ms = 1000.0 * np.array(cpu)
    print(f"cpu_ms_per_frame_median {np.median(ms):.2f} ms")
    print(f"cpu_ms_per_frame_p95 {np.percentile(ms, 95):.2f} ms")
    print(f"wall_ms_per_frame_median {1000.0 * np.median(wall):.2f} ms")
    print(f"frames_per_s_per_core {1000.0 / np.mean(ms):.1f} 1/s")
    print(f"cores_for_3_robots_at_15fps {45.0 * np.mean(ms) / 1000.0:.2f} cores")
    print(f"loadavg_1min {os.getloadavg()[0]:.2f} load")


if __name__ == "__main__":
    main()
