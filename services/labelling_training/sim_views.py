"""Simulated RGB-D views with ground truth: frames for measuring segmentation and for training.

A *scatter hall* is a small warehouse (rack rows at the back, a dock gate, walls) with forklifts,
people and loose pallets standing at random spots and headings on the open floor. Views put the
simulator's RGB-D camera (``RGBD_MOUNT``: 1 m up, level, 58 degrees) at a random distance and
bearing from one of them, rendered with the simulator's own renderer and depth noise.

Ground truth per view: every actor of which at least ``min_visible_fraction`` is seen (its pixels
with valid depth in the frame, over its pixels when rendered alone on a canvas three times the
image size, so border cuts, occlusion and range all count), with the box of its visible pixels;
as the article counts an object when at least half of it is visible.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from typing import NamedTuple

import numpy as np
import numpy.typing as npt

from services.object_labelling.camera import CameraIntrinsics, make_intrinsics
from services.object_labelling.errors import ObjectLabellingError
from services.object_labelling.ground_plane import GroundPlane
from services.simulator.actors import actor_boxes_at, actor_pose
from services.simulator.cameras import RGBD_MOUNT, RgbdModel, depth_image_mm
from services.simulator.layout import world_from_layout
from services.simulator.render import PinholeCamera, Textures, render_boxes
from services.simulator.world import ActorKind, Boxes, ObjectClass, World, concat_boxes

ACTOR_LABELS = {ActorKind.FORKLIFT: "forklift", ActorKind.PERSON: "human", ActorKind.PALLET: "pallet"}
"""The labeller's ROI class of each simulated actor kind."""
Box = tuple[int, int, int, int]
"""(row_min, col_min, row_max, col_max), inclusive pixels."""


class TruthObject(NamedTuple):
    """An actor in view: its class, id, the box of its visible pixels and the visible share of it."""

    label: str
    actor_id: str
    box: Box
    visible_fraction: float


class SimView(NamedTuple):
    """One rendered RGB-D frame and its ground truth.

    ``rgb`` (480, 640, 3) uint8; ``depth_mm`` (480, 640) uint16 (0 = no return); ``plane`` the
    floor in the optical frame (exact, from the mounting); ``objects`` the actors in view;
    ``actor_pixels`` (480, 640) int16, per pixel the index into ``actor_labels`` of the actor seen
    there (-1 for anything else); ``rack_fraction`` / ``gate_fraction`` the share of the image
    showing racking (uprights, beams and the pallets stored in them) / a gate, within depth range.
    """

    rgb: npt.NDArray[np.uint8]
    depth_mm: npt.NDArray[np.uint16]
    intrinsics: CameraIntrinsics
    plane: GroundPlane
    objects: tuple[TruthObject, ...]
    actor_pixels: npt.NDArray[np.int16]
    actor_labels: tuple[str, ...]
    rack_fraction: float
    gate_fraction: float


def scatter_hall(seed: int, *, n_actors: int = 9, min_gap_m: float = 0.4) -> World:
    """A 30 m x 20 m hall with two rack rows, a dock gate and ``n_actors`` standing objects.

    Actors (forklifts, people and loose pallets in turn) stand at random positions and headings
    on the open floor (y < 11 m), their bounding circles at least ``min_gap_m`` apart.
    """
    rng = np.random.default_rng(seed)
    kinds = ("forklift", "person", "pallet")
    radius = {"forklift": 1.5, "person": 0.3, "pallet": 0.75}
    placed: list[tuple[float, float, float]] = []
    actors = []
    for i in range(n_actors):
        kind = kinds[i % 3]
        for _attempt in range(200):
            x, y = rng.uniform(2.0, 28.0), rng.uniform(1.8, 10.5)
            if all(math.hypot(x - px, y - py) >= radius[kind] + pr + min_gap_m for px, py, pr in placed):
                break
        else:
            raise ObjectLabellingError(f"no room for actor {i} in scatter hall {seed}")
        placed.append((x, y, radius[kind]))
        yaw = rng.uniform(-math.pi, math.pi)
        actors.append({"id": f"{kind[0].upper()}{i}", "kind": kind, "speed_mps": 1e-9,
                       "path": [[x, y], [x + 0.01 * math.cos(yaw), y + 0.01 * math.sin(yaw)]]})
    return world_from_layout({
        "name": f"scatter-{seed}",
        "hall": {"length_m": 30.0, "width_m": 20.0},
        "gates": [{"id": "G1", "kind": "dock", "edge": "south", "offset_m": float(rng.uniform(3.0, 24.0)),
                   "width_m": 3.0},
                  {"id": "D1", "kind": "door", "edge": "west", "offset_m": float(rng.uniform(2.0, 8.0)),
                   "width_m": 1.0}],
        "blocks": [{"id": "A", "origin_m": [2.0, 12.5], "aisles": 1, "bays": 9, "aisle_width_m": 3.0,
                    "bay_pitch_m": 2.7, "rack_depth_m": 1.1, "levels": int(rng.integers(3, 5)),
                    "level_pitch_m": 1.5, "fill": float(rng.uniform(0.4, 0.9)), "cross_aisle_every": 20,
                    "cross_aisle_width_m": 3.0, "end_corridor_m": 1.0}],
        "open_areas": [],
        "chargers": [],
        "actors": actors,
        "seed": seed,
    })


def _intrinsics(camera: PinholeCamera) -> CameraIntrinsics:
    return make_intrinsics(camera.fx, camera.fy, camera.cx, camera.cy, camera.width, camera.height)


def _clear_of(boxes: Boxes, xy: npt.NDArray[np.float64], margin_m: float) -> bool:
    """Whether ``xy`` is more than ``margin_m`` from every box footprint."""
    c, s = np.cos(boxes.yaw_rad), np.sin(boxes.yaw_rad)
    dx, dy = xy[0] - boxes.centre_xy[:, 0], xy[1] - boxes.centre_xy[:, 1]
    local = np.abs(np.column_stack((c * dx + s * dy, -s * dx + c * dy))) - 0.5 * boxes.size_xy
    return bool((np.hypot(*np.clip(local, 0.0, None).T) > margin_m).all())


def _actor_boxes(world: World) -> list[Boxes]:
    return [actor_boxes_at(actor, actor_pose(actor, 0.0)) for actor in world.actors]


def render_view(world: World, base_xy: tuple[float, float], base_yaw_rad: float, *,
                rng: np.random.Generator, textures: Textures | None = None,
                model: RgbdModel | None = None, min_visible_fraction: float = 0.5) -> SimView:
    """Render the RGB-D camera of a robot at ``base_xy``, heading ``base_yaw_rad`` (actors at time 0).

    Parameters
    ----------
    world
        The scene; its actors are the ground-truth objects.
    base_xy, base_yaw_rad
        Robot pose in the map, metres and radians; the camera is mounted as ``RGBD_MOUNT``.
    rng
        Depth noise.
    textures
        Photo textures for pallets, forklifts and people (procedural ones when None).
    model
        The camera (default :class:`RgbdModel`).
    min_visible_fraction
        Actors seen less than this are not in the ground truth.
    """
    model = model or RgbdModel()
    camera = model.camera()
    c, s = math.cos(base_yaw_rad), math.sin(base_yaw_rad)
    base = np.eye(4)
    base[:2, :2] = [[c, -s], [s, c]]
    base[:2, 3] = base_xy
    optical = base @ RGBD_MOUNT
    parts = _actor_boxes(world)
    scene = concat_boxes([world.boxes, *parts])
    rendered = render_boxes(scene, optical, camera, textures=textures)
    depth = depth_image_mm(rendered.depth_m, model, rng)
    # the actor alone, on a canvas three times the image's size at half its resolution (4 pixels each)
    canvas = PinholeCamera(0.5 * camera.fx, 0.5 * camera.fy, 0.5 * camera.cx + 0.5 * camera.width,
                           0.5 * camera.cy + 0.5 * camera.height, 3 * camera.width // 2, 3 * camera.height // 2)
    objects = []
    n_static = len(world.boxes)
    actor_pixels = np.full(rendered.box.shape, -1, np.int16)
    first = n_static
    in_range = depth > 0
    for k, (actor, boxes) in enumerate(zip(world.actors, parts, strict=True)):
        last = first + len(boxes)
        seen = (rendered.box >= first) & (rendered.box < last) & in_range
        first = last
        if not seen.any():
            continue
        actor_pixels[seen] = k
        alone = 4 * int(np.count_nonzero(render_boxes(boxes, optical, canvas, far_m=model.max_range_m + 3.0).box >= 0))
        fraction = int(np.count_nonzero(seen)) / max(alone, 1)
        if fraction < min_visible_fraction:
            continue
        rows, cols = np.nonzero(seen)
        box = (int(rows.min()), int(cols.min()), int(rows.max()), int(cols.max()))
        objects.append(TruthObject(ACTOR_LABELS[actor.kind], actor.id, box, min(fraction, 1.0)))
    up = optical[:3, :3].T @ np.array([0.0, 0.0, 1.0])
    plane = GroundPlane((float(up[0]), float(up[1]), float(up[2])), float(optical[2, 3]))
    kind, static = rendered.kind, (rendered.box >= 0) & (rendered.box < n_static)
    rack = static & np.isin(kind, [ObjectClass.UPRIGHT, ObjectClass.BEAM, ObjectClass.PALLET, ObjectClass.LOAD])
    return SimView(rendered.rgb, depth, _intrinsics(camera), plane, tuple(objects), actor_pixels,
                   tuple(ACTOR_LABELS[a.kind] for a in world.actors), float(rack.mean()),
                   float((kind == ObjectClass.GATE).mean()))


def sample_views(world: World, rng: np.random.Generator, n_views: int, *, textures: Textures | None = None,
                 min_distance_m: float = 1.5, max_distance_m: float = 5.0, max_offset_rad: float = 0.4,
                 gate_share: float = 0.1, random_share: float = 0.1) -> Iterator[SimView]:
    """``n_views`` views of ``world`` from random robot poses on its open floor.

    Most views are aimed at an actor (picked in turn): the camera stands
    ``min_distance_m``-``max_distance_m`` from it at a random bearing, the actor up to
    ``max_offset_rad`` off the optical axis. A share ``gate_share`` is aimed the same way at a
    gate (2-8 m in front of it, from inside the hall), a share ``random_share`` looks in a random
    direction from a random spot. Robots never stand within 0.5 m of a box or 0.8 m of a wall, and
    the camera (0.35 m to the robot's left) never within 0.8 m of a box, beyond the depth camera's
    0.4 m minimum range.
    """
    if not world.actors:
        raise ObjectLabellingError(f"world {world.name} has no actors to look at")
    x_min, y_min = world.outline.min(axis=0)
    x_max, y_max = world.outline.max(axis=0)
    scene = concat_boxes([world.boxes, *_actor_boxes(world)])
    made = 0
    while made < n_views:
        draw = rng.random()
        if draw < random_share or (draw < random_share + gate_share and not world.gates):
            xy = rng.uniform([x_min, y_min], [x_max, y_max])
            look = rng.uniform(-math.pi, math.pi)
        else:
            if draw < random_share + gate_share:
                gate = world.gates[made % len(world.gates)]
                a, b = np.array(gate.a), np.array(gate.b)
                target = 0.5 * (a + b)
                inward = np.array([a[1] - b[1], b[0] - a[0]]) / np.hypot(*(b - a))  # left of a -> b: inside
                direction = math.atan2(-inward[1], -inward[0]) + rng.uniform(-0.6, 0.6)
                distance = rng.uniform(2.0, 8.0)
            else:
                ax, ay, _ = actor_pose(world.actors[made % len(world.actors)], 0.0)
                target = np.array([ax, ay])
                direction = rng.uniform(-math.pi, math.pi)
                distance = rng.uniform(min_distance_m, max_distance_m)
            xy = target - distance * np.array([math.cos(direction), math.sin(direction)])
            look = direction + rng.uniform(-max_offset_rad, max_offset_rad)
        yaw = look - math.pi / 2
        camera_xy = xy + RGBD_MOUNT[1, 3] * np.array([-math.sin(yaw), math.cos(yaw)])
        inside = x_min + 0.8 < xy[0] < x_max - 0.8 and y_min + 0.8 < xy[1] < y_max - 0.8
        if not inside or not _clear_of(scene, xy, 0.5) or not _clear_of(scene, camera_xy, 0.8):
            continue
        made += 1
        yield render_view(world, (float(xy[0]), float(xy[1])), yaw, rng=rng, textures=textures)
