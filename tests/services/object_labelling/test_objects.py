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


def test_a_long_object_seen_from_its_side_and_its_front_stays_one_object() -> None:
    tracker = ObjectTracker(merge_distance_m=1.0)
    side = Detection("forklift", 0.0, 0.0, 0.9, 1, "robot1", extent_m=2.9)  # the middle of its 3 m side
    front = Detection("forklift", 1.6, 0.9, 0.9, 2, "robot1", extent_m=1.1)  # its front face, 1.8 m away
    tracker.update([side])
    tracker.update([front])
    assert len(tracker.features()) == 1


def test_two_people_a_few_metres_apart_stay_two_objects() -> None:
    tracker = ObjectTracker(merge_distance_m=1.0)
    tracker.update([Detection("human", 0.0, 0.0, 0.9, 1, "robot1", extent_m=0.5)])
    tracker.update([Detection("human", 2.0, 0.0, 0.9, 2, "robot1", extent_m=0.5)])
    assert len(tracker.features()) == 2


def test_two_segments_of_one_truck_in_one_frame_are_one_object() -> None:
    tracker = ObjectTracker(merge_distance_m=1.0)
    body = Detection("forklift", 0.0, 0.0, 0.9, 1, "robot1", extent_m=1.7)
    mast = Detection("forklift", 1.0, 0.3, 0.8, 1, "robot1", extent_m=0.2)
    tracker.update([body, mast])
    [only] = tracker.features()
    assert only.properties["detections"] == 1
    tracker.update([Detection("forklift", 0.5, 0.1, 0.9, 2, "robot1", extent_m=2.4)])
    assert len(tracker.features()) == 1
