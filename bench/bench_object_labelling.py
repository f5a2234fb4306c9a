"""Object-labelling speed: CNN, per-step and end-to-end times on simulated 640x480 RGB-D, one BLAS thread.

Prints ``name value unit`` lines, CPU time (``time.process_time`` / the worker thread's clock) next
to wall time, and the load average: the machine may be shared.

Frames: a robot drives at 1.5 m/s past a pallet, two people and a forklift standing 2-4 m to its
left (the RGB-D camera looks left), rendered by the simulator at 30 frames/s (5 cm apart), so
most frames hold 2-3 ROIs (at most 3 go through the CNN). The classifier is trained quickly on
renders of other halls (its accuracy is not the point here; its cost does not depend on it).

1. CNN forward pass alone at batch 1 and 3 for several input sizes (fastest of 7, CPU).
2. The labeller on the frames: median wall time per step, CPU per frame, frames/s from the CPU
   time, with ROI reuse across frames (the default) and without (every ROI through the CNN
   every frame: the worst case).
3. The worker under ``run_stage`` on a real zenoh bus (robot in a second session, same process)
   and a SQLite store: the frames published in a loop at ``--rate-hz`` for ``--worker-seconds``;
   sustained labelled frames/s, CPU time of the worker thread per labelled frame, and the worker's
   median per-step times.

    PYTHONPATH=. .venv/bin/python bench/bench_object_labelling.py [--worker-seconds 20] [--rate-hz 30]
"""

from __future__ import annotations

import argparse
import math
import os
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np
from threadpoolctl import threadpool_limits

from services.labelling_training.commands import train_from_sources
from services.labelling_training.sim_views import SimView, render_view
from services.object_labelling import EfficientNetLite0, LabelModel, ObjectLabeller, PriorDatabase
from services.object_labelling.cnn import default_weights_path
from services.object_labelling.worker import LabellingStage
from services.simulator import photo_textures, rosmsgs, world_from_layout
from services.simulator.cameras import RGBD_MOUNT
from services.simulator.world import World
from shared.bus import Bus
from shared.settings import LabellingSettings, Settings, ZenohSettings
from shared.store import MapStore
from shared.transforms import from_matrix
from shared.worker import StageContext, run_stage
from tests.helpers import free_port

STAMP0_NS = 1_700_000_000_000_000_000


def _world() -> World:
    actors = [("pallet", 7.6, 4.6, 0.3), ("person", 8.9, 4.2, 1.6), ("person", 9.8, 5.0, 3.0),
              ("forklift", 11.6, 5.2, 0.2)]
    return world_from_layout({
        "name": "bench", "hall": {"length_m": 20.0, "width_m": 14.0}, "gates": [],
        "blocks": [{"id": "A", "origin_m": [2.0, 8.0], "aisles": 1, "bays": 5, "aisle_width_m": 3.0,
                    "bay_pitch_m": 2.7, "rack_depth_m": 1.1, "levels": 3, "level_pitch_m": 1.5, "fill": 0.7,
                    "cross_aisle_every": 10, "cross_aisle_width_m": 3.0, "end_corridor_m": 1.0}],
        "open_areas": [], "chargers": [], "seed": 0,
        "actors": [{"id": f"A{i}", "kind": kind, "speed_mps": 1e-9,
                    "path": [[x, y], [x + 0.01 * math.cos(yaw), y + 0.01 * math.sin(yaw)]]}
                   for i, (kind, x, y, yaw) in enumerate(actors)],
    })


def _frames(n: int) -> tuple[list[SimView], list[float]]:
    """``n`` frames 5 cm apart along y = 2 m from x = 6.5 m, and the robot's x at each."""
    world, rng, textures = _world(), np.random.default_rng(0), photo_textures()
    xs = [6.5 + 0.05 * k for k in range(n)]
    return [render_view(world, (x, 2.0), 0.0, rng=rng, textures=textures) for x in xs], xs


def _best_cpu_ms(run: Any, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        start = time.process_time()
        run()
        times.append(time.process_time() - start)
    return 1000.0 * float(np.min(times))


def _bench_cnn(net: EfficientNetLite0) -> None:
    rng = np.random.default_rng(0)
    for size in (128, 96):
        for batch in (1, 3):
            images = rng.integers(0, 256, (batch, size, size, 3), dtype=np.uint8)
            net.features(images)
            print(f"cnn_forward_{size}px_batch{batch}_cpu {_best_cpu_ms(lambda i=images: net.features(i), 7):.1f} ms")


def _bench_labeller(net: EfficientNetLite0, model: LabelModel, frames: list[SimView]) -> None:
    for reuse, name in ((10, "roi_reuse"), (0, "no_roi_reuse")):
        view = frames[0]
        labeller = ObjectLabeller(net, model, PriorDatabase.read_csv(), view.intrinsics, view.plane,
                                  roi_reuse_frames=reuse)
        steps: dict[str, list[float]] = {}
        rois, cnn_rois = [], []
        start = time.process_time()
        for view in frames:
            result = labeller.label(view.rgb, view.depth_mm)
            rois.append(len(result.objects))
            cnn_rois.append(result.cnn_rois)
            for step, seconds in result.timings_s.items():
                steps.setdefault(step, []).append(seconds)
        cpu_ms = 1000 * (time.process_time() - start) / len(frames)
        for step, values in steps.items():
            print(f"labeller_{name}_step_{step} {1000 * np.median(values):.2f} ms (median wall)")
        print(f"labeller_{name}_rois_per_frame {np.mean(rois):.2f} rois (max {max(rois)})")
        print(f"labeller_{name}_cnn_rois_per_frame {np.mean(cnn_rois):.2f} rois")
        print(f"labeller_{name}_cpu_per_frame {cpu_ms:.1f} ms")
        print(f"labeller_{name}_frames_per_cpu_second {1000 / cpu_ms:.1f} frames/s")


def _messages(view: SimView, x: float, stamp_ns: int) -> list[tuple[str, str, Any]]:
    base = np.eye(4)
    base[:2, 3] = (x, 2.0)
    intrinsics = view.intrinsics
    k = np.array([[intrinsics.fx, 0.0, intrinsics.cx], [0.0, intrinsics.fy, intrinsics.cy], [0.0, 0.0, 1.0]])
    t, q = from_matrix(base @ RGBD_MOUNT)
    return [
        ("tf", *rosmsgs.tf_message([rosmsgs.transform_stamped(stamp_ns, "map", "camera", tuple(t), q)])),
        ("rgbd/camera_info", *rosmsgs.camera_info(stamp_ns, "camera", width=640, height=480, k=k)),
        ("rgbd/color/image_raw", *rosmsgs.image(stamp_ns, "camera", view.rgb)),
        ("rgbd/depth/image_raw", *rosmsgs.image(stamp_ns, "camera", view.depth_mm)),
    ]


class _Timed:
    """A stage whose ``run`` also records the CPU time of the thread running it."""

    def __init__(self, stage: LabellingStage) -> None:
        self.stage, self.cpu_s = stage, 0.0

    def run(self, stop: threading.Event) -> None:
        start = time.thread_time()
        try:
            self.stage.run(stop)
        finally:
            self.cpu_s = time.thread_time() - start


def _bench_worker(model_path: Path, frames: list[SimView], xs: list[float], *, seconds: float,
                  rate_hz: float) -> None:
    stages: list[_Timed] = []
    with tempfile.TemporaryDirectory() as tmp:
        store = MapStore(f"sqlite:///{tmp}/aisle.db")
        store.upgrade()
        listen = ZenohSettings(listen=[f"tcp/127.0.0.1:{free_port()}"])
        settings = Settings(database_url=store.url, zenoh=listen)
        stop = threading.Event()

        def factory(context: StageContext) -> _Timed:
            stages.append(_Timed(LabellingStage(context, LabellingSettings(model_path=model_path))))
            return stages[-1]

        robot = ZenohSettings(listen=[], connect=listen.listen)
        with Bus.open(listen, domain_id=0) as bus, Bus.open(robot, domain_id=0) as robot_bus:
            worker = threading.Thread(target=run_stage, args=("object_labelling", factory),
                                      kwargs={"bus": bus, "store": store, "settings": settings, "stop": stop})
            worker.start()
            while bus.alive_workers() != ["object_labelling"]:
                time.sleep(0.05)
            publishers = {topic: robot_bus.publisher(topic, msgtype, namespace="robot1", drop_when_congested=True)
                          for topic, msgtype, _ in _messages(frames[0], xs[0], STAMP0_NS)}
            counters = stages[-1].stage.context.counters
            start, sent, measured = time.monotonic(), 0, None
            while (elapsed := time.monotonic() - start) < seconds + 3.0:
                if measured is None and elapsed >= 3.0:  # warm-up: teach-in, first CNN runs
                    measured = (counters.snapshot().get("object_labelling.frames_labelled", 0), time.monotonic(),
                                time.process_time())
                k = sent % len(frames)
                for topic, _, message in _messages(frames[k], xs[k], STAMP0_NS + round(sent * 1e9 / rate_hz)):
                    publishers[topic].publish(message)
                sent += 1
                time.sleep(max(0.0, start + sent / rate_hz - time.monotonic()))
            assert measured is not None
            labelled = counters.snapshot().get("object_labelling.frames_labelled", 0) - measured[0]
            wall, process_cpu = time.monotonic() - measured[1], time.process_time() - measured[2]
            stop.set()
            worker.join()
        store.close()
    timed = stages[-1]
    total = counters.snapshot().get("object_labelling.frames_labelled", 0)
    print(f"worker_frames_offered {rate_hz:.1f} frames/s")
    print(f"worker_frames_labelled {labelled / wall:.1f} frames/s (wall, {labelled} frames in {wall:.1f} s)")
    print(f"worker_thread_cpu_per_frame {1000 * timed.cpu_s / max(total, 1):.1f} ms (whole run incl. warm-up)")
    print(f"process_cpu_per_labelled_frame {1000 * process_cpu / max(labelled, 1):.1f} ms (incl. the publisher)")
    for name, values in timed.stage.step_times_s.items():
        print(f"worker_step_{name} {1000 * np.median(values):.2f} ms (median wall)")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=90)
    parser.add_argument("--worker-seconds", type=float, default=20.0)
    parser.add_argument("--rate-hz", type=float, default=30.0)
    args = parser.parse_args()
    print(f"load_average_1min {os.getloadavg()[0]:.2f} processes")
    frames, xs = _frames(args.frames)
    with tempfile.TemporaryDirectory() as tmp:
        model_path = Path(tmp) / "model.npz"
        model = train_from_sources(model_path, data_dir=None, sim_views=40)
        net = EfficientNetLite0.load(default_weights_path())
        with threadpool_limits(limits=1, user_api="blas"):
            _bench_cnn(net)
            _bench_labeller(net, model, frames)
        _bench_worker(model_path, frames, xs, seconds=args.worker_seconds, rate_hz=args.rate_hz)
    print(f"load_average_1min {os.getloadavg()[0]:.2f} processes")


if __name__ == "__main__":
    main()
