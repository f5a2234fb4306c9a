import numpy as np

from services.load_scenes import evidence_predicates, support_relations
from services.load_scenes import synthetic as syn
from services.load_scenes.boxes import LOAD, PALLET, SUPPORT, Boxes, concat, hull_half
from services.load_scenes.predicates import moved_evidence, same_evidence

Row = tuple[int, tuple[float, float, float], tuple[float, float, float]]


def _boxes(rows: list[Row], sigma: float = 0.01) -> Boxes:
    kind = np.array([k for k, _, _ in rows], np.int64)
    centre = np.array([c for _, c, _ in rows], float)
    size = np.array([s for _, _, s in rows], float)
    n = len(rows)
    return Boxes(centre=centre, half=hull_half(size, np.zeros(n)), size=size, yaw=np.zeros(n),
                 sigma=np.where(kind[:, None] == SUPPORT, 0.0, sigma) * np.ones((n, 3)), kind=kind,
                 level=np.zeros(n, np.int64), score=np.ones(n))


FLOOR = (SUPPORT, (0.0, 0.6, -0.05), (2.7, 1.2, 0.1))


def test_a_load_on_a_pallet_on_the_floor_rests_and_is_held_up() -> None:
    b = _boxes([FLOOR, (PALLET, (0.0, 0.6, 0.072), (0.8, 1.2, 0.144)), (LOAD, (0.0, 0.6, 0.644), (0.7, 1.0, 1.0))])
    ev = evidence_predicates(b)
    assert ev.rests_on[1, 0] and ev.rests_on[2, 1]
    assert ev.contact[1, 2] and ev.contact[2, 1] and ev.higher[2, 1] and not ev.higher[1, 2]
    assert not ev.intersect.any() and not ev.hover.any() and ev.stable.all()
    supports, unstable = support_relations(ev.contact, ev.rests_on, ev.stable)
    assert supports[0, 1] and supports[1, 2] and supports.sum() == 2
    assert not unstable.any()


def test_side_by_side_boxes_touch_without_resting_on_each_other() -> None:
    b = _boxes([FLOOR, (PALLET, (-0.405, 0.6, 0.072), (0.8, 1.2, 0.144)), (PALLET, (0.405, 0.6, 0.072),
                                                                            (0.8, 1.2, 0.144))])
    ev = evidence_predicates(b)
    assert ev.contact[1, 2] and not ev.rests_on[1, 2] and not ev.rests_on[2, 1]
    supports, unstable = support_relations(ev.contact, ev.rests_on, ev.stable)
    assert not supports[1, 2] and not supports[2, 1] and not unstable.any()


def test_overlapping_boxes_intersect_and_a_box_in_the_air_hovers() -> None:
    b = _boxes([FLOOR, (PALLET, (0.0, 0.6, 0.072), (0.8, 1.2, 0.144)), (PALLET, (0.3, 0.6, 0.072), (0.8, 1.2, 0.144)),
                (LOAD, (0.9, 0.3, 1.2), (0.3, 0.3, 0.3))])
    ev = evidence_predicates(b)
    assert ev.intersect[1, 2] and ev.intersect[2, 1] and not ev.contact[1, 2]
    assert ev.hover.tolist() == [False, False, False, True]


def test_contact_tolerance_grows_with_the_estimates_sigma() -> None:
    rows = [FLOOR, (PALLET, (0.0, 0.6, 0.072 + 0.05), (0.8, 1.2, 0.144))]  # 5 cm above the floor
    assert not evidence_predicates(_boxes(rows, sigma=0.005)).rests_on[1, 0]
    assert evidence_predicates(_boxes(rows, sigma=0.02)).rests_on[1, 0]


def test_a_load_with_its_centre_beyond_the_edge_below_is_unstable_and_only_touches() -> None:
    b = _boxes([FLOOR, (PALLET, (0.0, 0.6, 0.072), (0.8, 1.2, 0.144)), (LOAD, (0.0, -0.15, 0.344), (0.6, 0.6, 0.4))])
    ev = evidence_predicates(b)
    assert ev.rests_on[2, 1] and not ev.stable[2] and ev.stable[1]
    supports, unstable = support_relations(ev.contact, ev.rests_on, ev.stable)
    assert not supports[1, 2] and unstable[1, 2] and unstable[2, 1]


def test_moving_one_box_updates_the_evidence_as_a_full_recomputation_would() -> None:
    rng = np.random.default_rng(3)
    for k in range(12):
        t = syn.synthetic_bay(5, k).truth
        b = concat(t)
        b = Boxes(b.centre, b.half, b.size, b.yaw, np.full_like(b.sigma, 0.02), b.kind, b.level, b.score)
        ev = evidence_predicates(b)
        i = int(rng.integers(len(b)))
        centre = b.centre.copy()
        centre[i] += rng.normal(0.0, 0.05, 3)
        moved = Boxes(centre, b.half, b.size, b.yaw, b.sigma, b.kind, b.level, b.score)
        assert same_evidence(moved_evidence(ev, moved, i), evidence_predicates(moved))
