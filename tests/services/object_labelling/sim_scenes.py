"""Simulated warehouse scenes for the worker tests: a small hall, a classifier trained on renders, and
per-cone ground truth by ray casting.

The test hall has one rack block at the back and a forklift, a person and a loose pallet standing
in front of it; the robot drives along ``y = 2 m`` with the RGB-D camera looking left at them. The
classifier is trained on renders of a *different* hall (other positions, headings and distances).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import numpy.typing as npt
from sklearn.svm import LinearSVC

from services.object_labelling import EfficientNetLite0, LabelModel, SvmBank, resize_for_cnn
from services.simulator import RgbdModel, World, world_from_layout
from services.simulator.actors import actor_boxes_at, actor_pose, dynamic_boxes
from services.simulator.cameras import RGBD_MOUNT, photo_textures
from services.simulator.lidar import Segments, cast_rays
from services.simulator.render import render_boxes
from services.simulator.world import ObjectClass, concat_boxes

ROI_OF_KIND = {ObjectClass.PALLET: "pallet", ObjectClass.LOAD: "pallet", ObjectClass.FORKLIFT: "forklift",
               ObjectClass.PERSON: "human"}
"""Labeller ROI class of each simulated object class; anything else is background."""
ROBOT_Y_M = 2.0
INPUT_SIZE_PX = 96


def _layout(name: str, actors: list[dict[str, Any]], *, seed: int) -> dict[str, Any]:
    return {
        "name": name,
        "hall": {"length_m": 24.0, "width_m": 14.0},
        "gates": [{"id": "G1", "kind": "dock", "edge": "north", "offset_m": 20.0, "width_m": 3.0}],
        "blocks": [{"id": "A", "origin_m": [2.0, 8.0], "aisles": 1, "bays": 6, "aisle_width_m": 3.0,
                    "bay_pitch_m": 2.7, "rack_depth_m": 1.1, "levels": 3, "level_pitch_m": 1.5, "fill": 0.7,
                    "cross_aisle_every": 10, "cross_aisle_width_m": 3.0, "end_corridor_m": 1.0}],
        "open_areas": [],
        "chargers": [],
        "actors": actors,
        "seed": seed,
    }


def labelling_hall() -> World:
    """The hall the robot drives through: objects 2.5-3.5 m to the left of its path."""
    return world_from_layout(_layout("labelling-test", [
        {"id": "F1", "kind": "forklift", "path": [[6.0, 5.0]], "speed_mps": 0.0},
        {"id": "P1", "kind": "person", "path": [[11.0, 4.6], [12.0, 4.6]], "speed_mps": 0.2},
        {"id": "L1", "kind": "pallet", "path": [[16.0, 4.8]], "speed_mps": 0.0},
    ], seed=3))


def robot_waypoints() -> list[list[float]]:
    """The robot's straight route past the objects."""
    return [[2.0, ROBOT_Y_M], [19.0, ROBOT_Y_M]]


def _training_world(seed: int) -> World:
    rng = np.random.default_rng(seed)
    actors = []
    for i, kind in enumerate(("forklift", "person", "pallet", "forklift", "person", "pallet")):
        x, y = 3.0 + 3.2 * i + rng.uniform(-0.5, 0.5), rng.uniform(4.2, 5.5)
        actors.append({"id": f"T{i}", "kind": kind, "path": [[x, y], [x + 0.1, y + rng.uniform(-0.2, 0.2)]],
                       "speed_mps": 0.01})
    return world_from_layout(_layout(f"labelling-train-{seed}", actors, seed=seed))


def _optical(base_x: float, base_y: float, yaw: float) -> npt.NDArray[np.float64]:
    c, s = math.cos(yaw), math.sin(yaw)
    base = np.eye(4)
    base[:2, :2] = [[c, -s], [s, c]]
    base[:2, 3] = (base_x, base_y)
    return np.asarray(base @ RGBD_MOUNT)


def _sample_crops(world: World, rng: np.random.Generator, views: int
                  ) -> tuple[list[npt.NDArray[np.uint8]], list[str], list[npt.NDArray[np.uint8]], list[int]]:
    """ROI crops with labels (actors by their box pixels, background windows) and whole images with rack flags."""
    camera = RgbdModel().camera()
    textures = photo_textures()
    crops: list[npt.NDArray[np.uint8]] = []
    labels: list[str] = []
    images: list[npt.NDArray[np.uint8]] = []
    racks: list[int] = []
    n_static = len(world.boxes)
    per_actor = np.cumsum([0] + [len(actor_boxes_at(a, actor_pose(a, 0.0))) for a in world.actors])
    for view in range(views):
        actor_index = view % len(world.actors)
        actor = world.actors[actor_index]
        time_s = float(rng.uniform(0.0, 20.0))
        ax, ay, _ = actor_pose(actor, time_s)
        distance, bearing = rng.uniform(1.8, 4.0), rng.uniform(-1.2, 1.2)
        cam_x, cam_y = ax - distance * math.sin(bearing), ay - distance * math.cos(bearing)
        look = math.atan2(ay - cam_y, ax - cam_x) + rng.uniform(-0.25, 0.25)
        scene = concat_boxes([world.boxes, dynamic_boxes(world, time_s)])
        rendered = render_boxes(scene, _optical(cam_x, cam_y, look - math.pi / 2), camera, far_m=9.0,
                                textures=textures)
        images.append(rendered.rgb)
        racks.append(int(np.isin(rendered.kind, [ObjectClass.UPRIGHT, ObjectClass.BEAM]).mean() > 0.03))
        for k in range(len(world.actors)):
            mask = (rendered.box >= n_static + per_actor[k]) & (rendered.box < n_static + per_actor[k + 1])
            rows, cols = np.nonzero(mask)
            if rows.size < 400:
                continue
            kinds = rendered.kind[rows, cols]
            label = ROI_OF_KIND[ObjectClass(int(np.bincount(kinds[kinds >= 0]).argmax()))]
            crops.append(rendered.rgb[rows.min() : rows.max() + 1, cols.min() : cols.max() + 1])
            labels.append(label)
        for _ in range(2):  # background windows without any actor in them
            h, w = int(rng.integers(80, 300)), int(rng.integers(60, 300))
            r0, c0 = int(rng.integers(0, 480 - h)), int(rng.integers(0, 640 - w))
            if (rendered.box[r0 : r0 + h, c0 : c0 + w] >= n_static).mean() < 0.02:
                crops.append(rendered.rgb[r0 : r0 + h, c0 : c0 + w])
                labels.append("background")
    return crops, labels, images, racks


def _bank(features: npt.NDArray[np.float32], targets: dict[str, npt.NDArray[np.bool_]]) -> SvmBank:
    mean = features.mean(axis=0)
    scale = features.std(axis=0) + 1e-3
    x = (features - mean) / scale
    coefs, intercepts = [], []
    for y in targets.values():
        if y.all() or not y.any():  # nothing to learn: this class is never (or always) predicted
            coefs.append(np.zeros(x.shape[1]))
            intercepts.append(1.0 if y.all() else -1.0)
            continue
        svm = LinearSVC(C=1e-3, class_weight="balanced", max_iter=20000).fit(x, y)
        coefs.append(svm.coef_[0])
        intercepts.append(float(svm.intercept_[0]))
    return SvmBank(tuple(targets), np.asarray(coefs, np.float32), np.asarray(intercepts, np.float32),
                   mean.astype(np.float32), scale.astype(np.float32))


def _features(net: EfficientNetLite0, images: list[npt.NDArray[np.uint8]]) -> npt.NDArray[np.float32]:
    batch = np.stack([resize_for_cnn(image, size_px=INPUT_SIZE_PX) for image in images])
    return np.concatenate([net.features(batch[i : i + 16]) for i in range(0, len(batch), 16)])


def train_sim_model(net: EfficientNetLite0, out: Path, *, views: int = 36, seed: int = 0) -> LabelModel:
    """A model trained on renders of a training hall, written to ``out`` (weights hash left empty)."""
    rng = np.random.default_rng(seed)
    crops, labels, images, racks = _sample_crops(_training_world(seed + 100), rng, views)
    names = np.array(labels)
    roi = _bank(_features(net, crops), {c: names == c for c in ("pallet", "forklift", "human")})
    rack = np.array(racks, dtype=bool)
    scene = _bank(_features(net, [np.asarray(cv2.resize(i, (160, 120)), np.uint8) for i in images]),
                  {"rack": rack, "gate": np.zeros_like(rack)})
    model = LabelModel(roi, scene, INPUT_SIZE_PX, "", 0.0)
    model.save(out)
    return model


def cone_truth(world: World, time_s: float, origin_xy: npt.NDArray[np.float64],
               bearings_map_rad: npt.NDArray[np.float64], heights_m: npt.NDArray[np.float64]) -> list[str]:
    """Per cone, the labeller class of the first box a horizontal ray hits at half the cone's height
    (``"background"`` for racks, walls and the rest, ``"none"`` when nothing is hit within 6 m)."""
    scene = concat_boxes([world.boxes, dynamic_boxes(world, time_s)])
    out = []
    cuts: dict[float, Segments] = {}
    for bearing, height in zip(bearings_map_rad, heights_m, strict=True):
        cut = round(max(0.08, 0.5 * float(height)), 1)
        segments = cuts.get(cut) or cuts.setdefault(cut, Segments.from_boxes(scene, height_m=cut))
        _, hit = cast_rays(origin_xy, float(bearing), 1e-3, 1, [(segments, None)], max_range_m=6.0)
        kind = int(hit[0])
        out.append("none" if kind < 0 else ROI_OF_KIND.get(ObjectClass(kind), "background"))
    return out
