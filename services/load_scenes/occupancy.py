"""Bin occupancy from a bay's scene graph and its depth views; fusion of successive views of a bin.

A bin (one level of a bay) is *seen* when enough depth rays pass through its front opening; it is seen *empty*
only when the width of the opening they left uncrossed is less than a pallet's (an oblique view that sees one half
of a bin empty says nothing of the other half, where the pallet may stand). Its probability of holding something
is that of its objects (1 - prod(1 - p) over the scene's pallets and loads at that level, false estimates included
with their low probability) raised to ``unexplained_probability`` when enough depth points inside the bin meet
none of the scene's boxes (an object nobody detected), and kept ``view_error`` away from 0 and 1 (one view is
never certain). Seen bins are ``occupied`` or ``empty`` when that probability (or its complement) reaches
``decide_probability``, else ``unknown`` (the seed's 0.4-0.6 band of no decision); bins not seen are ``unknown``.

Successive views of a bin add their log-odds after the older sum is scaled by ``history_weight``: two views
agreeing make the bin surer, and one clear view of a change (a pallet taken out) still flips it.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
import numpy.typing as npt
from pydantic import BaseModel, Field

from services.load_scenes.boxes import beam_boxes, boxes_from_nodes, level_tops, validate_bay
from services.load_scenes.errors import SceneError
from services.load_scenes.likelihood import LikelihoodSettings, entry_distances, prepare_rays
from services.load_scenes.model import (
    Bay,
    BinOccupancy,
    DepthEvidence,
    Flag,
    ObjectKind,
    Occupancy,
    Relation,
    SceneGraph,
)


class OccupancySettings(BaseModel):
    """When a bin counts as seen, what unexplained points mean, and how views are fused."""

    min_rays: int = Field(15, ge=1, description="Rays through a bin's front opening for it to count as seen.")
    min_unexplained: int = Field(12, ge=1, description="Unexplained points in a bin that make it occupied.")
    unexplained_probability: float = Field(0.9, gt=0.5, lt=1.0)
    decide_probability: float = Field(0.6, ge=0.5, lt=1.0)
    view_error: float = Field(0.01, gt=0.0, lt=0.5, description="How sure one view can be at most (1 - this).")
    history_weight: float = Field(0.5, ge=0.0, le=1.0, description="Scale of the older log-odds per new view.")
    max_log_odds: float = Field(9.0, gt=0.0)
    max_uncovered_m: float = Field(0.6, ge=0.0, description="Width of a bin's opening no ray crossed, metres, "
                                                            "up to which it can be seen empty (narrower than a "
                                                            "pallet).")


class BinEvidence(NamedTuple):
    """What the depth views say per level of a bay."""

    rays: npt.NDArray[np.int64]
    """(L,) rays through each level's front opening."""
    unexplained: npt.NDArray[np.int64]
    """(L,) points inside each level's volume that no box of the scene explains."""
    covered: npt.NDArray[np.float64] | None = None
    """(L,) share of the front opening's width the rays crossed (in strips of ``strip_m``); None: all of it."""


def bin_evidence(
    bay: Bay, graph: SceneGraph, evidence: list[DepthEvidence], settings: LikelihoodSettings | None = None, *,
    strip_m: float = 0.3,
) -> BinEvidence:
    """Count, per level, the rays through the front opening and the points the scene leaves unexplained.

    Parameters
    ----------
    bay, graph
        The bay and its scene graph (false estimates are left out of the boxes that explain points).
    evidence
        The depth views the graph was inferred from.
    settings
        The ray subsample and the range noise (a point more than 3 sigma before its ray's first box is
        unexplained too).
    strip_m
        Width of the strips of the front opening whose share crossed by rays is ``covered``.
    """
    s = settings or LikelihoodSettings()
    validate_bay(bay)
    if graph.bay != bay.key:
        raise SceneError(f"scene graph of bay {graph.bay!r} given with bay {bay.key!r}")
    levels = np.asarray(bay.levels_z_m, float)
    tops = level_tops(bay)
    n = levels.size
    rays = prepare_rays(bay, evidence, s)
    o, d, r = rays.origin, rays.direction, rays.range_m
    with np.errstate(divide="ignore", invalid="ignore"):
        t0 = np.where(d[:, 1] > 1e-9, -o[:, 1] / d[:, 1], np.inf)
    cross = o + d * np.where(np.isfinite(t0), t0, 0.0)[:, None]
    level = np.searchsorted(levels, cross[:, 2], side="right") - 1
    through = (np.isfinite(t0) & (t0 >= 0.0) & (r > t0) & (np.abs(cross[:, 0]) < 0.5 * bay.width_m)
               & (level >= 0) & (cross[:, 2] < tops[np.clip(level, 0, n - 1)]))
    seen = np.bincount(level[through], minlength=n)[:n]
    strips = max(1, round(bay.width_m / strip_m))
    strip = np.clip(((cross[:, 0] / bay.width_m + 0.5) * strips).astype(np.int64), 0, strips - 1)
    crossed = np.unique(level[through] * strips + strip[through])
    covered = np.bincount(crossed // strips, minlength=n)[:n] / strips

    nodes = [nd for nd in graph.nodes if nd.kind != ObjectKind.BEAM and Flag.FALSE_ESTIMATE not in nd.flags]
    boxes = boxes_from_nodes(bay, nodes)
    bc, bh = beam_boxes(bay)
    table = np.concatenate([entry_distances(rays, bc, 2.0 * bh, np.zeros(len(bc))),
                            entry_distances(rays, boxes.centre, boxes.size, boxes.yaw)], axis=1)
    expected = table.min(axis=1, initial=np.inf)
    unexplained = ~rays.background & (r < expected - 3.0 * s.range_sigma_m)
    point_level = np.searchsorted(levels, rays.point[:, 2], side="right") - 1
    # A point between a level's top and the next support (beside a beam, or under the pallet standing on it) is
    # in no bin: counted in the level below, the load above made an empty bin occupied.
    inside = rays.point[:, 2] < tops[np.clip(point_level, 0, n - 1)]
    ok = unexplained & (point_level >= 0) & inside
    return BinEvidence(rays=seen.astype(np.int64),
                       unexplained=np.bincount(point_level[ok], minlength=n)[:n].astype(np.int64),
                       covered=covered.astype(np.float64))


def bin_occupancy(
    bay: Bay, graph: SceneGraph, evidence: BinEvidence, *, last_seen_ns: int | None = None,
    settings: OccupancySettings | None = None,
) -> list[BinOccupancy]:
    """Each bin of the bay: empty, occupied (by which objects, stable, hidden) or unknown, with confidence.

    Parameters
    ----------
    bay, graph
        The bay and its scene graph.
    evidence
        Rays through each level's opening and unexplained points (:func:`bin_evidence`).
    last_seen_ns
        When the views were taken; the graph's stamp when None.
    settings
        Thresholds; defaults when None.

    Returns
    -------
    list of BinOccupancy
        One per level, in level order; ``detail`` holds ``p_occupied``, ``rays``, ``unexplained_points`` and
        ``covered``. A bin whose opening the rays left uncrossed over more than ``max_uncovered_m`` and where
        nothing was found is not seen (``unknown``).
    """
    s = settings or OccupancySettings()
    validate_bay(bay)
    if graph.bay != bay.key:
        raise SceneError(f"scene graph of bay {graph.bay!r} given with bay {bay.key!r}")
    n = len(bay.levels_z_m)
    if evidence.rays.shape != (n,) or evidence.unexplained.shape != (n,):
        raise SceneError(f"bin evidence must have one entry per level ({n})")
    unstable = {x for e in graph.edges if e.relation == Relation.UNSTABLE_CONTACT for x in (e.source, e.target)}
    out = []
    for level, bin_id in enumerate(bay.bin_ids):
        nodes = [nd for nd in graph.nodes if nd.kind != ObjectKind.BEAM and nd.level == level]
        p = 1.0 - math.prod(1.0 - nd.probability for nd in nodes)
        if evidence.unexplained[level] >= s.min_unexplained:
            p = max(p, s.unexplained_probability)
        p = min(max(p, s.view_error), 1.0 - s.view_error)
        kept = sorted((nd for nd in nodes if Flag.FALSE_ESTIMATE not in nd.flags),
                      key=lambda nd: (nd.kind != ObjectKind.PALLET, nd.centre[2]))
        whole = evidence.covered is None or bool(
            (1.0 - evidence.covered[level]) * bay.width_m <= s.max_uncovered_m + 1e-9)
        seen = bool(evidence.rays[level] >= s.min_rays) and (whole or p >= 0.5)
        out.append(_bin(bin_id, bay.key, p, seen=seen, views=int(seen), stamp=(last_seen_ns or graph.stamp_ns),
                        objects=tuple(nd.id for nd in kept), unstable=any(nd.id in unstable for nd in kept),
                        hidden=any(Flag.HIDDEN_BELOW in nd.flags for nd in kept), settings=s,
                        detail={"p_occupied": p, "rays": int(evidence.rays[level]),
                                "unexplained_points": int(evidence.unexplained[level]),
                                "covered": 1.0 if evidence.covered is None else float(evidence.covered[level])}))
    return out


def _bin(bin_id: str, bay: str | None, p: float, *, seen: bool, views: int, stamp: int | None, objects: tuple[str, ...],
         unstable: bool, hidden: bool, settings: OccupancySettings, detail: dict[str, object]) -> BinOccupancy:
    sure = max(p, 1.0 - p)
    if not seen or sure < settings.decide_probability:
        state = Occupancy.UNKNOWN
    else:
        state = Occupancy.OCCUPIED if p >= 0.5 else Occupancy.EMPTY
    occupied = state == Occupancy.OCCUPIED
    return BinOccupancy(bin_id=bin_id, state=state, confidence=sure, last_seen_ns=stamp if seen else None,
                        objects=objects if occupied else (), views=views, stable=(not unstable) if occupied else None,
                        hidden=hidden and occupied, bay=bay, detail=detail)


def fuse_occupancy(
    previous: BinOccupancy | None, new: BinOccupancy, *, settings: OccupancySettings | None = None,
) -> BinOccupancy:
    """One bin's state after another view: log-odds added to the older ones scaled by ``history_weight``.

    A view that did not see the bin (``views == 0``) leaves the previous state as it was.

    Raises
    ------
    SceneError
        When the two are about different bins.
    """
    s = settings or OccupancySettings()
    if previous is None or new.views == 0:
        return previous or new
    if previous.bin_id != new.bin_id:
        raise SceneError(f"cannot fuse bin {previous.bin_id!r} with bin {new.bin_id!r}")
    if previous.views == 0:
        return new
    logit = s.history_weight * _log_odds(previous) + _log_odds(new)
    logit = max(-s.max_log_odds, min(s.max_log_odds, logit))
    p = 1.0 / (1.0 + math.exp(-logit))
    last = max(x for x in (previous.last_seen_ns, new.last_seen_ns, 0) if x is not None)
    return _bin(new.bin_id, new.bay, p, seen=True, views=previous.views + new.views, stamp=last,
                objects=new.objects, unstable=new.stable is False, hidden=new.hidden, settings=s,
                detail={**new.detail, "p_occupied": p})


def _log_odds(b: BinOccupancy) -> float:
    stored = b.detail.get("p_occupied")
    p = float(stored) if isinstance(stored, float | int) else (
        b.confidence if b.state == Occupancy.OCCUPIED else 1.0 - b.confidence)
    p = min(max(p, 1e-6), 1.0 - 1e-6)
    return math.log(p / (1.0 - p))
