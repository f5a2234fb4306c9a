import dataclasses
import math

import numpy as np
import pytest

from services.load_scenes import InferenceSettings, infer_bay_scene, infer_scene
from services.load_scenes import synthetic as syn
from services.load_scenes.boxes import PALLET, SUPPORT, to_bay_frame, to_map_frame
from services.load_scenes.model import BoxEstimate, Flag, ObjectKind, Relation

CLEAN = syn.NoiseModel(miss_rate=0.0, ghosts_per_bay=0.0, limited_view_rate=0.0)


def _planted() -> tuple[syn.SyntheticBay, str, str, np.ndarray]:
    """A clean bay with an empty level: a ghost pallet planted there, a detected pallet under a load dropped."""
    for k in range(60):
        sb = syn.synthetic_bay(7, k, CLEAN)
        levels = set(sb.truth.level[sb.truth.kind != SUPPORT].tolist())
        empty = [lv for lv in range(len(sb.bay.levels_z_m)) if lv not in levels]
        by_truth = {t: e for e, t in sb.estimate_truth.items()}
        pallets = [i for i in range(len(sb.truth_ids)) if sb.truth.kind[i] == PALLET and sb.truth.centre[i, 1] < 1.0
                   and sb.truth_ids[i] in by_truth]
        if sb.bay.deep != 1 or not empty or not pallets:
            continue
        level, pallet = empty[0], pallets[0]
        z = sb.bay.levels_z_m[level] + 0.072
        centre = np.array([[0.0, 0.6, z]])
        sb_map = to_map_frame(sb.bay, centre)[0]
        ghost = BoxEstimate(id="ghost", kind=ObjectKind.PALLET, centre=(float(sb_map[0]), float(sb_map[1]), z),
                            size=(0.8, 1.2, 0.144), yaw_rad=sb.bay.yaw_rad - 0.5 * math.pi, sigma=(0.02, 0.02, 0.015),
                            sigma_yaw_rad=0.01, score=0.8, stamp_ns=1, bay=sb.bay.key)
        dropped = by_truth[sb.truth_ids[pallet]]
        estimates = [e for e in sb.estimates if e.id != dropped] + [ghost]
        return dataclasses.replace(sb, estimates=estimates), "ghost", dropped, sb.truth.centre[pallet]
    raise AssertionError("no bay to plant in")


def test_mcmc_finds_a_planted_ghost_and_a_planted_hidden_pallet() -> None:
    sb, ghost, dropped, pallet_centre = _planted()
    graph = infer_scene(sb.bay, sb.estimates, sb.evidence)
    false = {n.id for n in graph.nodes if Flag.FALSE_ESTIMATE in n.flags}
    assert false == {ghost}
    hidden = [n for n in graph.nodes if Flag.HIDDEN_BELOW in n.flags]
    near = [n for n in hidden if n.kind == ObjectKind.PALLET
            and np.linalg.norm(to_bay_frame(sb.bay, np.array([n.centre]))[0] - pallet_centre) < 0.15]
    assert len(near) == 1
    carried = {e.target for e in graph.edges if e.source == near[0].id and e.relation == Relation.SUPPORTS}
    assert carried and all(Flag.FALSE_ESTIMATE not in n.flags for n in graph.nodes if n.id in carried)
    probability = {n.id: n.probability for n in graph.nodes}
    assert probability[ghost] < 0.5 < probability[near[0].id]
    assert dropped not in probability


def test_every_kept_object_of_a_scene_rests_on_its_kind_of_base() -> None:
    for k in range(6):
        sb = syn.synthetic_bay(8, k)
        graph = infer_scene(sb.bay, sb.estimates, sb.evidence)
        kind = {n.id: n.kind for n in graph.nodes}
        held = {e.target: e.source for e in graph.edges if e.relation == Relation.SUPPORTS}
        unstable = {x for e in graph.edges if e.relation == Relation.UNSTABLE_CONTACT for x in (e.source, e.target)}
        for n in graph.nodes:
            if n.kind == ObjectKind.BEAM or Flag.FALSE_ESTIMATE in n.flags:
                continue
            assert n.id in held or n.id in unstable, n.id
            if n.id in held:
                want = {ObjectKind.BEAM} if n.kind == ObjectKind.PALLET else {ObjectKind.PALLET, ObjectKind.LOAD}
                assert kind[held[n.id]] in want


def test_an_overhanging_carton_is_an_unstable_contact_not_a_support() -> None:
    for k in range(200):
        sb = syn.synthetic_bay(9, k, CLEAN, overhang_rate=1.0)
        if sb.overhanging:
            break
    by_truth = {t: e for e, t in sb.estimate_truth.items()}
    graph = infer_scene(sb.bay, sb.estimates, sb.evidence)
    for t in sb.overhanging:
        e = by_truth[t]
        assert not any(x.target == e and x.relation == Relation.SUPPORTS for x in graph.edges)
        assert any(e in (x.source, x.target) and x.relation == Relation.UNSTABLE_CONTACT for x in graph.edges)


def test_without_depth_the_context_decides_and_the_chain_is_bounded() -> None:
    sb = syn.synthetic_bay(7, 1)
    result = infer_bay_scene(sb.bay, sb.estimates, [], InferenceSettings(max_sweeps=3))
    assert result.graph.iterations <= 3
    assert {n.id for n in result.graph.nodes} >= {e.id for e in sb.estimates}
    assert all(0.0 <= n.probability <= 1.0 for n in result.graph.nodes)


@pytest.mark.parametrize("field", ["max_sweeps", "pose_proposals"])
def test_settings_reject_nonsense(field: str) -> None:
    with pytest.raises(ValueError, match=field):
        InferenceSettings(**{field: 0})
