"""Tracking the dynamic objects currently seen."""

from __future__ import annotations

from services.object_labelling.objects import Detection, ObjectTracker


def _seen(label: str, x: float, stamp_ns: int) -> Detection:
    return Detection(label, x, 0.0, 0.8, stamp_ns, "robot1")


def test_detections_near_a_known_object_of_the_same_class_update_it() -> None:
    tracker = ObjectTracker(merge_distance_m=1.0)
    tracker.update([_seen("forklift", 0.0, 1), _seen("human", 0.3, 1)])
    tracker.update([_seen("forklift", 0.5, 2), _seen("human", 5.0, 2)])
    features = tracker.features()
    assert sorted(f.properties["class"] for f in features) == ["forklift", "human", "human"]
    forklift = next(f for f in features if f.properties["class"] == "forklift")
    assert forklift.geometry["coordinates"] == [0.5, 0.0]
    assert (forklift.properties["first_seen_ns"], forklift.properties["last_seen_ns"]) == (1, 2)


def test_objects_not_seen_for_a_while_are_dropped_and_mark_a_change() -> None:
    tracker = ObjectTracker(forget_after_s=1.0)
    tracker.update([_seen("pallet", 0.0, 0), _seen("human", 3.0, 900_000_000)])
    tracker.features()
    tracker.forget(1_500_000_000)
    assert tracker.changed and [f.properties["class"] for f in tracker.features()] == ["human"]
