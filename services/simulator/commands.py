"""Entry points for the ``aisle sim`` commands: build a world, run a survey into a bag, run live."""

from __future__ import annotations

import logging
import threading
import time
from collections import Counter
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from services.simulator.bag import write_bag
from services.simulator.cameras import fisheye_sensor, rgbd_sensor
from services.simulator.errors import SimulatorError
from services.simulator.files import actor_tracks, read_layout, write_ground_truth
from services.simulator.layout import world_from_layout
from services.simulator.live import publish_live
from services.simulator.presets import demo_layout, hall_layout, random_layout
from services.simulator.route import survey_route, waypoint_route
from services.simulator.stream import CameraSensor, RobotSpec, robot_trajectory, simulate
from services.simulator.world import World
from shared.bus import Bus

log = logging.getLogger(__name__)

PRESETS = {"demo": demo_layout, "hall": hall_layout}
CAMERAS = ("fisheye", "rgbd")


def load_world(layout: Path | str | None = None, *, seed: int | None = None) -> World:
    """A world from a layout YAML file, a preset name (``demo``, ``hall``), or (``layout`` None) a
    random layout drawn with ``seed``."""
    if layout is None:
        return world_from_layout(random_layout(0 if seed is None else seed))
    if str(layout) in PRESETS:
        return world_from_layout(PRESETS[str(layout)]())
    return world_from_layout(read_layout(Path(layout)))


def sim_world(layout: Path | str | None, out: Path, *, seed: int | None = None, resolution_m: float = 0.05
              ) -> dict[str, Path]:
    """``aisle sim world LAYOUT.yaml --out DIR`` / ``--random --seed N``: write the world's ground truth."""
    return write_ground_truth(load_world(layout, seed=seed), out, resolution_m=resolution_m)


def _cameras(names: Sequence[str], *, fisheye_rate_hz: float, rgbd_rate_hz: float) -> tuple[CameraSensor, ...]:
    unknown = set(names) - set(CAMERAS)
    if unknown:
        raise SimulatorError(f"unknown cameras {sorted(unknown)}; known: {list(CAMERAS)}")
    sensors = []
    if "fisheye" in names:
        sensors.append(fisheye_sensor(rate_hz=fisheye_rate_hz))
    if "rgbd" in names:
        sensors.append(rgbd_sensor(rate_hz=rgbd_rate_hz))
    return tuple(sensors)


def robot_specs(world: World, *, robots: int = 1, waypoints: Sequence[Sequence[float]] | None = None,
                speed_mps: float = 1.2, seed: int = 0, cameras: Sequence[str] = (),
                fisheye_rate_hz: float = 5.0, rgbd_rate_hz: float = 5.0) -> list[RobotSpec]:
    """Robots ``robot1``..``robotN``: each surveys every aisle starting at a different aisle (or all
    drive ``waypoints``, started 10 s apart), with the named ``cameras``."""
    if robots < 1:
        raise SimulatorError(f"robots must be at least 1, got {robots}")
    sensors = _cameras(cameras, fisheye_rate_hz=fisheye_rate_hz, rgbd_rate_hz=rgbd_rate_hz)
    aisles = sum(1 for a in world.areas if "start" in a.detail)
    specs = []
    for k in range(robots):
        if waypoints is not None:
            route, delay = waypoint_route(world, np.asarray(waypoints, dtype=np.float64)), 10.0 * k
        else:
            route, delay = survey_route(world, first_aisle=(k * aisles) // robots), 0.0
        specs.append(RobotSpec(f"robot{k + 1}", route, speed_mps=speed_mps, seed=seed + k, start_delay_s=delay,
                               cameras=sensors))
    return specs


def sim_run(world: World, out: Path, *, robots: int = 1, waypoints: Sequence[Sequence[float]] | None = None,
            speed_mps: float = 1.2, seed: int = 0, cameras: Sequence[str] = (), fisheye_rate_hz: float = 5.0,
            rgbd_rate_hz: float = 5.0, resolution_m: float = 0.05) -> Counter[str]:
    """``aisle sim run ... --out BAG``: survey ``world`` into an MCAP rosbag2 ``out`` and write the
    ground truth (with actor and robot tracks) beside it in ``<out>.truth/``; messages per topic."""
    specs = robot_specs(world, robots=robots, waypoints=waypoints, speed_mps=speed_mps, seed=seed, cameras=cameras,
                        fisheye_rate_hz=fisheye_rate_hz, rgbd_rate_hz=rgbd_rate_hz)
    trajectories = {spec.namespace: robot_trajectory(spec) for spec in specs}
    duration = max(float(t.t_s[-1]) + spec.start_delay_s for spec, t in zip(specs, trajectories.values(), strict=True))
    tracks: dict[str, Any] = actor_tracks(world, duration_s=duration)
    for spec, trajectory in zip(specs, trajectories.values(), strict=True):
        step = max(1, round(spec.odom_rate_hz))
        tracks[spec.namespace] = np.column_stack([trajectory.t_s[::step] + spec.start_delay_s, trajectory.pose[::step]])
    log.info("simulating %d robot(s) for %.0f s in %s", len(specs), duration, world.name)
    written = write_bag(simulate(world, specs, trajectories=trajectories), out)
    write_ground_truth(world, Path(f"{out}.truth"), resolution_m=resolution_m, tracks=tracks)
    return written


def sim_live(bus: Bus, stop: threading.Event, world: World, *, robots: int = 1,
             waypoints: Sequence[Sequence[float]] | None = None, speed_mps: float = 1.2, seed: int = 0,
             cameras: Sequence[str] = (), rate: float = 1.0) -> Counter[str]:
    """``aisle sim run ... --live``: publish the survey onto the bus in real time (``rate`` x)."""
    specs = robot_specs(world, robots=robots, waypoints=waypoints, speed_mps=speed_mps, seed=seed, cameras=cameras)
    start_ns = time.time_ns()
    return publish_live(bus, simulate(world, specs, start_ns=start_ns), stop, start_ns=start_ns, rate=rate)
