"""Where the dynamic objects are at a given time, as poses and as boxes."""

from __future__ import annotations

import math

import numpy as np

from services.simulator.world import Actor, ActorKind, Boxes, ObjectClass, World, concat_boxes, empty_boxes

_FORKLIFT_COLOUR = (230, 170, 20)
_PERSON_COLOURS = ((40, 40, 60), (240, 120, 20))  # trousers, high-visibility vest
_PALLET_COLOUR = (170, 130, 80)
_LOAD_COLOUR = (190, 160, 110)


def actor_pose(actor: Actor, time_s: float) -> tuple[float, float, float]:
    """(x, y, yaw) of ``actor`` at ``time_s``: it walks its path to the end and back, forever."""
    path = actor.path
    if len(path) < 2 or actor.speed_mps <= 0:
        return float(path[0, 0]), float(path[0, 1]), 0.0
    lengths = np.hypot(*np.diff(path, axis=0).T)
    total = float(lengths.sum())
    if total <= 0:
        return float(path[0, 0]), float(path[0, 1]), 0.0
    s = (actor.speed_mps * time_s) % (2 * total)
    backwards = s > total
    if backwards:
        s = 2 * total - s
    cumulative = np.concatenate([[0.0], np.cumsum(lengths)])
    i = int(np.clip(np.searchsorted(cumulative, s, side="right") - 1, 0, len(lengths) - 1))
    fraction = (s - cumulative[i]) / lengths[i] if lengths[i] > 0 else 0.0
    a, b = path[i], path[i + 1]
    x, y = a + fraction * (b - a)
    yaw = math.atan2(b[1] - a[1], b[0] - a[0]) + (math.pi if backwards else 0.0)
    return float(x), float(y), math.atan2(math.sin(yaw), math.cos(yaw))


def _boxes(rows: list[tuple[float, float, float, float, float, float, float, ObjectClass, tuple[int, int, int]]]
           ) -> Boxes:
    """Boxes from (x, y, z0, z1, length, width, yaw, kind, colour) tuples."""
    a = np.array([r[:7] for r in rows], dtype=np.float64)
    return Boxes(a[:, 0:2].copy(), a[:, 2:4].copy(), a[:, 4:6].copy(), a[:, 6].copy(),
                 np.array([r[7] for r in rows], np.int8), np.array([r[8] for r in rows], np.uint8))


def actor_boxes_at(actor: Actor, pose: tuple[float, float, float]) -> Boxes:
    """The boxes of ``actor`` standing at ``pose``: a forklift body and mast, a person's legs and
    torso, or a loose pallet with its load."""
    x, y, yaw = pose
    c, s = math.cos(yaw), math.sin(yaw)

    def at(forward: float, left: float) -> tuple[float, float]:
        return x + c * forward - s * left, y + s * forward + c * left

    if actor.kind is ActorKind.FORKLIFT:
        return _boxes([
            (*at(0.0, 0.0), 0.05, 2.1, 2.2, 1.15, yaw, ObjectClass.FORKLIFT, _FORKLIFT_COLOUR),
            (*at(1.2, 0.0), 0.05, 2.4, 0.2, 0.9, yaw, ObjectClass.FORKLIFT, (60, 60, 60)),
            (*at(1.75, 0.3), 0.05, 0.15, 1.0, 0.12, yaw, ObjectClass.FORKLIFT, (60, 60, 60)),
            (*at(1.75, -0.3), 0.05, 0.15, 1.0, 0.12, yaw, ObjectClass.FORKLIFT, (60, 60, 60)),
        ])
    if actor.kind is ActorKind.PERSON:
        return _boxes([
            (*at(0.0, 0.12), 0.0, 0.85, 0.14, 0.13, yaw, ObjectClass.PERSON, _PERSON_COLOURS[0]),
            (*at(0.0, -0.12), 0.0, 0.85, 0.14, 0.13, yaw, ObjectClass.PERSON, _PERSON_COLOURS[0]),
            (*at(0.0, 0.0), 0.85, 1.5, 0.26, 0.44, yaw, ObjectClass.PERSON, _PERSON_COLOURS[1]),
            (*at(0.0, 0.0), 1.5, 1.75, 0.2, 0.18, yaw, ObjectClass.PERSON, (220, 180, 150)),
        ])
    return _boxes([
        (x, y, 0.0, 0.15, 1.2, 0.8, yaw, ObjectClass.PALLET, _PALLET_COLOUR),
        (x, y, 0.15, 1.2, 1.15, 0.78, yaw, ObjectClass.LOAD, _LOAD_COLOUR),
    ])


def dynamic_boxes(world: World, time_s: float) -> Boxes:
    """Boxes of every actor of ``world`` at ``time_s`` seconds into the run."""
    if not world.actors:
        return empty_boxes()
    return concat_boxes([actor_boxes_at(a, actor_pose(a, time_s)) for a in world.actors])
