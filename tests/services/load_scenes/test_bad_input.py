import dataclasses
import math

import numpy as np
import pytest

from services.load_scenes import SceneError, infer_bay_scene
from services.load_scenes import synthetic as syn
from services.load_scenes.model import BoxEstimate, DepthEvidence


def _bad(sb: syn.SyntheticBay) -> list[BoxEstimate]:
    e = sb.estimates[0]
    return [
        dataclasses.replace(e, id="nan", centre=(math.nan, e.centre[1], e.centre[2])),
        dataclasses.replace(e, id="flat", size=(e.size[0], 0.0, e.size[2])),
        dataclasses.replace(e, id="far", centre=(e.centre[0] + 40.0, e.centre[1], e.centre[2])),
        dataclasses.replace(e, id="other", bay="R77/000"),
        dataclasses.replace(e, id="sure", score=1.5),
    ]


def test_bad_estimates_are_skipped_with_a_reason_and_the_rest_inferred() -> None:
    sb = syn.synthetic_bay(4, 0)
    result = infer_bay_scene(sb.bay, sb.estimates + _bad(sb), sb.evidence)
    reasons = {s.id: s.reason for s in result.skipped}
    assert set(reasons) == {"nan", "flat", "far", "other", "sure"}
    assert "not finite" in reasons["nan"] and "not positive" in reasons["flat"]
    assert "outside the bay" in reasons["far"] and "R77/000" in reasons["other"] and "score" in reasons["sure"]
    assert {n.id for n in result.graph.nodes} >= {e.id for e in sb.estimates}


def test_a_bay_without_levels_is_an_error_naming_the_bay() -> None:
    sb = syn.synthetic_bay(4, 0)
    bay = dataclasses.replace(sb.bay, levels_z_m=(), bin_ids=())
    with pytest.raises(SceneError, match="no levels"):
        infer_bay_scene(bay, sb.estimates, sb.evidence)


def test_levels_out_of_order_are_an_error() -> None:
    sb = syn.synthetic_bay(4, 0)
    bay = dataclasses.replace(sb.bay, levels_z_m=(0.0, 3.0, 1.5), bin_ids=("a", "b", "c"))
    with pytest.raises(SceneError, match="rising"):
        infer_bay_scene(bay, sb.estimates, sb.evidence)


def test_malformed_depth_is_an_error_and_nan_points_are_dropped() -> None:
    sb = syn.synthetic_bay(4, 0)
    with pytest.raises(SceneError, match=r"\(N, 3\)"):
        infer_bay_scene(sb.bay, sb.estimates, [DepthEvidence(origin=(0.0, 0.0, 1.0), points=np.zeros((4, 2)),
                                                             stamp_ns=1)])
    view = sb.evidence[0]
    noisy = view.points.copy()
    noisy[::7] = np.nan
    result = infer_bay_scene(sb.bay, sb.estimates, [dataclasses.replace(view, points=noisy)])
    assert len(result.graph.nodes) >= len(sb.estimates)


def test_a_bay_with_no_estimates_has_only_its_supports() -> None:
    sb = syn.synthetic_bay(4, 0)
    graph = infer_bay_scene(sb.bay, [], sb.evidence).graph
    assert len(graph.nodes) == len(sb.bay.levels_z_m) and graph.edges == ()
