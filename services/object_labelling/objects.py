"""The dynamic objects currently seen, in the map frame, as ``object`` map features.

Detections of forklifts, people and loose pallets from every robot are associated with the
objects already known by class and distance (greedy, closest first); an object not seen for
``forget_after_s`` is dropped. The set is what the worker commits every few seconds.

A detection is placed on the face the camera sees, so the same 3 m forklift seen from its side
and from its front gives points up to about half its length apart: the association gate is
``merge_distance_m`` plus half the larger visible extent of the detection and the object. One
object can also give several segments in one frame (a truck body and its mast); detections of a
class within that gate of each other in one frame are first merged into one.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field
from typing import NamedTuple

from services.object_labelling.errors import ObjectLabellingError
from shared.store import Feature
from shared.vocabulary import FeatureKind


class Detection(NamedTuple):
    """One labelled object of one frame: class, position on the floor in map metres, confidence in
    [0, 1], and the width of its visible face in metres."""

    label: str
    x_m: float
    y_m: float
    confidence: float
    stamp_ns: int
    namespace: str
    extent_m: float = 0.0


@dataclass
class TrackedObject:
    """An object seen at least once; position and robot of the latest detection, mean confidence."""

    key: str
    label: str
    x_m: float
    y_m: float
    confidence: float
    first_seen_ns: int
    last_seen_ns: int
    namespace: str
    detections: int = 1
    extent_m: float = 0.0
    """Largest visible extent seen, metres."""

    def feature(self) -> Feature:
        """The ``object`` feature: a GeoJSON Point in map metres with class, times and robot."""
        return Feature(
            FeatureKind.OBJECT,
            self.key,
            {"type": "Point", "coordinates": [self.x_m, self.y_m]},
            {
                "class": self.label,
                "confidence": self.confidence,
                "first_seen_ns": self.first_seen_ns,
                "last_seen_ns": self.last_seen_ns,
                "robot": self.namespace,
                "detections": self.detections,
            },
            self.confidence,
        )


@dataclass
class ObjectTracker:
    """Currently seen dynamic objects.

    Parameters
    ----------
    merge_distance_m
        A detection within this distance plus half the larger visible extent (its own and the
        object's) of a known object of the same class is that object.
    forget_after_s
        Objects not detected for this long (detection stamps) are dropped.
    """

    merge_distance_m: float = 1.0
    forget_after_s: float = 10.0
    objects: dict[str, TrackedObject] = field(default_factory=dict)
    changed: bool = False
    """Whether the set changed since :meth:`features` was last called."""
    _ids: itertools.count[int] = field(default_factory=itertools.count, repr=False)

    def __post_init__(self) -> None:
        if not (self.merge_distance_m > 0 and self.forget_after_s > 0):
            raise ObjectLabellingError(
                f"need merge_distance_m > 0 and forget_after_s > 0, got {self.merge_distance_m}, {self.forget_after_s}"
            )

    def _gate(self, a_extent_m: float, b_extent_m: float) -> float:
        return self.merge_distance_m + 0.5 * max(a_extent_m, b_extent_m)

    def _merged(self, detections: list[Detection]) -> list[Detection]:
        """One frame's detections with those of a class within the gate of each other merged (widest first)."""
        merged: list[Detection] = []
        for d in sorted(detections, key=lambda d: -d.extent_m):
            for k, m in enumerate(merged):
                distance = math.hypot(m.x_m - d.x_m, m.y_m - d.y_m)
                if m.label == d.label and distance <= self._gate(m.extent_m, d.extent_m):
                    w = m.extent_m / (m.extent_m + d.extent_m) if m.extent_m + d.extent_m > 0 else 0.5
                    merged[k] = m._replace(
                        x_m=w * m.x_m + (1 - w) * d.x_m,
                        y_m=w * m.y_m + (1 - w) * d.y_m,
                        confidence=max(m.confidence, d.confidence),
                        extent_m=max(m.extent_m, distance + 0.5 * (m.extent_m + d.extent_m)),
                    )
                    break
            else:
                merged.append(d)
        return merged

    def update(self, detections: list[Detection]) -> None:
        """Associate one frame's detections with the known objects (each object takes at most one)."""
        detections = self._merged(detections)
        pairs = sorted(
            (math.hypot(o.x_m - d.x_m, o.y_m - d.y_m), i, o.key)
            for i, d in enumerate(detections)
            for o in self.objects.values()
            if o.label == d.label and math.hypot(o.x_m - d.x_m, o.y_m - d.y_m) <= self._gate(o.extent_m, d.extent_m)
        )
        taken_detections: set[int] = set()
        taken_objects: set[str] = set()
        for _, i, key in pairs:
            if i in taken_detections or key in taken_objects:
                continue
            taken_detections.add(i)
            taken_objects.add(key)
            d, o = detections[i], self.objects[key]
            o.x_m, o.y_m, o.namespace = d.x_m, d.y_m, d.namespace
            o.confidence += (d.confidence - o.confidence) / (o.detections + 1)
            o.detections += 1
            o.last_seen_ns = max(o.last_seen_ns, d.stamp_ns)
            o.extent_m = max(o.extent_m, d.extent_m)
        for i, d in enumerate(detections):
            if i not in taken_detections:
                key = f"{d.label}-{next(self._ids)}"
                self.objects[key] = TrackedObject(
                    key, d.label, d.x_m, d.y_m, d.confidence, d.stamp_ns, d.stamp_ns, d.namespace, extent_m=d.extent_m
                )
        self.changed = self.changed or bool(detections)

    def forget(self, now_ns: int) -> None:
        """Drop objects whose last detection is more than ``forget_after_s`` before ``now_ns``."""
        horizon = now_ns - round(self.forget_after_s * 1e9)
        stale = [key for key, o in self.objects.items() if o.last_seen_ns < horizon]
        for key in stale:
            del self.objects[key]
        self.changed = self.changed or bool(stale)

    def features(self) -> list[Feature]:
        """The current objects as features (and the change flag cleared)."""
        self.changed = False
        return [o.feature() for o in self.objects.values()]
