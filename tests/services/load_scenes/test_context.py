import math

import numpy as np

from services.load_scenes import ContextSettings, evidence_predicates, infer_context, log_prior
from services.load_scenes.boxes import LOAD, PALLET, SUPPORT, Boxes, hull_half

FLOOR = (SUPPORT, (0.0, 0.6, -0.05), (2.7, 1.2, 0.1), 1.0)
PALLET_A = (PALLET, (-0.9, 0.6, 0.072), (0.8, 1.2, 0.144), 0.9)
LOAD_A = (LOAD, (-0.9, 0.6, 0.544), (0.7, 1.0, 0.8), 0.9)


def _boxes(rows: list[tuple[int, tuple[float, float, float], tuple[float, float, float], float]]) -> Boxes:
    kind = np.array([r[0] for r in rows], np.int64)
    size = np.array([r[2] for r in rows], float)
    n = len(rows)
    return Boxes(centre=np.array([r[1] for r in rows], float), half=hull_half(size, np.zeros(n)), size=size,
                 yaw=np.zeros(n), sigma=np.where(kind[:, None] == SUPPORT, 0.0, 0.01) * np.ones((n, 3)), kind=kind,
                 level=np.zeros(n, np.int64), score=np.array([r[3] for r in rows]))


def _prior(b: Boxes, present: list[bool], added: list[bool] | None = None) -> float:
    s = ContextSettings()
    ev = evidence_predicates(b, k_sigma=s.k_sigma, min_tolerance_m=s.min_tolerance_m)
    return log_prior(b, ev, np.array(present), np.array(added or [False] * len(b)), s)


def test_rules_reject_a_hovering_load_and_accept_it_once_false() -> None:
    b = _boxes([FLOOR, PALLET_A, (LOAD, (0.9, 0.6, 0.8), (0.7, 1.0, 0.6), 0.9)])
    assert _prior(b, [True, True, True]) == -math.inf
    assert math.isfinite(_prior(b, [True, True, False]))


def test_rules_reject_intersecting_objects_unless_one_is_false() -> None:
    b = _boxes([FLOOR, PALLET_A, (PALLET, (-0.6, 0.6, 0.072), (0.8, 1.2, 0.144), 0.5)])
    assert _prior(b, [True, True, True]) == -math.inf
    assert math.isfinite(_prior(b, [True, True, False]))
    assert _prior(b, [True, True, False]) > _prior(b, [True, False, True])  # the surer detection stays


def test_rules_reject_a_load_on_the_beams_and_a_pallet_on_a_load() -> None:
    on_floor = _boxes([FLOOR, (LOAD, (0.9, 0.6, 0.3), (0.7, 1.0, 0.6), 0.9)])
    assert _prior(on_floor, [True, True]) == -math.inf
    pallet_on_load = _boxes([FLOOR, PALLET_A, LOAD_A, (PALLET, (-0.9, 0.6, 1.016), (0.8, 1.2, 0.144), 0.9)])
    assert _prior(pallet_on_load, [True, True, True, True]) == -math.inf


def test_an_added_hidden_pallet_makes_the_hovering_load_possible() -> None:
    b = _boxes([FLOOR, LOAD_A, PALLET_A])
    assert _prior(b, [True, True, False], [False, False, True]) == -math.inf
    assert math.isfinite(_prior(b, [True, True, True], [False, False, True]))
    # a hidden object with nothing on it is not added
    assert _prior(b, [True, False, True], [False, False, True]) == -math.inf


def test_exact_inference_says_hidden_for_a_hovering_load_and_false_for_a_pallet_on_nothing() -> None:
    b = _boxes([FLOOR, LOAD_A, (PALLET, (0.9, 0.6, 0.9), (0.8, 1.2, 0.144), 0.9)])
    ctx = infer_context(b, ContextSettings())
    assert ctx.p_hidden[1] > 0.6 and ctx.p_false[1] < 0.4
    assert ctx.p_false[2] > 0.99
    assert ctx.p_false[0] == 0.0 and ctx.p_hidden[0] == 0.0


def test_exact_inference_blames_the_weaker_of_two_intersecting_detections() -> None:
    b = _boxes([FLOOR, PALLET_A, (PALLET, (-0.6, 0.6, 0.072), (0.8, 1.2, 0.144), 0.4)])
    ctx = infer_context(b, ContextSettings())
    assert ctx.p_false[2] > 0.6
    assert ctx.p_false[1] < 0.4
    assert ctx.p_false[1] + ctx.p_false[2] >= 1.0 - 1e-9  # never both there
