"""Data-driven MCMC over a bay's scene (seed 003 section 4.9): box estimates + depth -> scene graph.

The hypothesis space holds the bay's supports, every detected box and, data-driven from the context
inference, candidate hidden objects: under each detection that would otherwise rest on nothing of its kind
(a load over a missed pallet, a second-deep load whose pallet the front pallet hides) a box filling the gap
down to what is below (a pallet on a beam pair or the floor, a load on a pallet or load). A scene is which of
them are present and their poses; its posterior is the context prior (:func:`context.log_prior`) times the
depth likelihood (:mod:`likelihood`) times the detector's Gaussian on each detection's pose.

The chain starts where the exact context marginals point (detections with p(false) < 0.5, candidates with
p(hidden) > 0.5) and runs sweeps; each sweep

1. (in the first ``pose_sweeps`` sweeps) for each present object draws ``pose_proposals`` Gaussian pose
   corrections, weights them by the sensor model (likelihood and detector term), takes the best and accepts
   it by eq. 4.5 with the proposal probabilities of eqs. 4.6-4.7 (which leaves the prior ratio);
2. proposes, in random order, to flip each detection (a removal: a false estimate), each candidate (an
   addition: a hidden object) and each candidate with its detection, accepted by Metropolis (the flips are
   symmetric).

It stops when a sweep flips nothing and the best posterior improved by less than ``converged_log``, after
``max_sweeps`` or when ``time_budget_s`` of process time is spent; from the best scene seen at the end of a
sweep, greedy flips (only gains) climb to the mode, which is returned. Node
probabilities are the Gibbs conditionals of presence in that scene (the posterior odds of the object being
there, all else fixed); an edge's is the product of its ends'.
"""

from __future__ import annotations

import dataclasses
import math
import time
from typing import NamedTuple

import numpy as np
import numpy.typing as npt
from pydantic import BaseModel, Field

from services.load_scenes.boxes import (
    CODE_KIND,
    LOAD,
    PALLET,
    SUPPORT,
    Boxes,
    Skipped,
    beam_boxes,
    concat,
    hull_half,
    levels_of,
    supports,
    to_map_frame,
    usable_estimates,
    validate_bay,
    yaw_to_map,
)
from services.load_scenes.context import (
    ContextResult,
    ContextSettings,
    allowed_base,
    infer_context,
    log_prior,
    object_terms,
)
from services.load_scenes.errors import SceneError
from services.load_scenes.likelihood import (
    LikelihoodSettings,
    Rays,
    entry_distances,
    prepare_rays,
    ray_log_likelihoods,
)
from services.load_scenes.model import (
    Bay,
    BoxEstimate,
    DepthEvidence,
    Flag,
    Relation,
    SceneEdge,
    SceneGraph,
    SceneNode,
)
from services.load_scenes.predicates import (
    Evidence,
    evidence_predicates,
    moved_evidence,
    same_evidence,
    support_relations,
)


class InferenceSettings(BaseModel):
    """The scene inference: context rules, the ray likelihood and the chain."""

    context: ContextSettings = Field(default_factory=ContextSettings)
    likelihood: LikelihoodSettings = Field(default_factory=LikelihoodSettings)
    max_sweeps: int = Field(6, ge=1)
    min_sweeps: int = Field(1, ge=1)
    converged_log: float = Field(0.05, ge=0.0)
    time_budget_s: float = Field(0.05, gt=0.0, description="Process time one bay may take.")
    pose_proposals: int = Field(6, ge=1, description="Gaussian pose corrections drawn per object and sweep.")
    pose_sweeps: int = Field(1, ge=0, description="Sweeps that move poses (later ones only flip).")
    pose_step_sigma: float = Field(1.0, gt=0.0, description="Their spread in the estimate's sigmas.")
    pose_clip_sigma: float = Field(4.0, gt=0.0, description="How far (in sigmas) a pose may move from where the "
                                   "chain starts.")
    detector_weight: float = Field(1.0, ge=0.0, description="Weight of the detector's Gaussian on each pose.")
    pallet_height_m: float = Field(0.144, gt=0.0)
    max_pallet_height_m: float = Field(0.25, gt=0.0)
    min_hidden_height_m: float = Field(0.1, gt=0.0, description="Least height of an added hidden load (a hidden "
                                       "pallet: half of ``pallet_height_m``).")
    pallet_footprint_m: tuple[float, float] = Field((0.8, 1.2), description="Least footprint of an added "
                                                    "hidden pallet along the bay's front and depth (EU pallet).")
    snap_m: float = Field(0.1, ge=0.0, description="How far a detection hovering over its base is lowered onto it "
                          "before the chain.")
    max_objects: int = Field(40, ge=1, description="Detections per bay beyond which the scene is refused.")
    seed: int = 0


class SceneInference(NamedTuple):
    """A bay's scene graph and the estimates left out of it."""

    graph: SceneGraph
    skipped: list[Skipped]
    log_posterior: float


class _Space(NamedTuple):
    """Supports, detections and candidate hidden objects; the units the chain flips."""

    boxes: Boxes
    added: npt.NDArray[np.bool_]
    units: list[npt.NDArray[np.int64]]
    """Indices flipped together: one detection, or the one or two boxes of a candidate."""
    carriers: list[int]
    """Per unit, the detection a candidate was added under (-1 for detections)."""
    origin_centre: npt.NDArray[np.float64]


class _Snapshot(NamedTuple):
    boxes: Boxes
    present: npt.NDArray[np.bool_]
    ev: Evidence
    table: npt.NDArray[np.float64]
    expected: npt.NDArray[np.float64]
    ll: npt.NDArray[np.float64]
    prior_value: float


class _Chain:
    """The scene's state and the posterior's terms, updated incrementally.

    The rays' entry table (N, K) is computed once; per ray the predicted range and log-likelihood are kept,
    so a flip re-scores only the rays that meet the flipped boxes and a pose move only the rays near the moved
    box (within ``_reach`` of its estimate, where moves are clipped).
    """

    def __init__(self, space: _Space, rays: Rays, fixed_min: npt.NDArray[np.float64],
                 settings: InferenceSettings, present: npt.NDArray[np.bool_]) -> None:
        self.space = space
        self.rays = rays
        self.fixed_min = fixed_min
        self.s = settings
        self.boxes = space.boxes
        self.present = present
        self.detected = (self.boxes.kind != SUPPORT) & ~space.added
        b = self.boxes
        obj = np.flatnonzero(b.kind != SUPPORT)
        moving = np.flatnonzero(b.kind != SUPPORT)
        self.reach = self.s.pose_clip_sigma * np.maximum(b.sigma, 1e-3)
        self.start = b.centre.copy()
        both = entry_distances(rays, np.concatenate([b.centre[obj], b.centre[moving]]),
                               np.concatenate([b.size[obj], b.size[moving] + 2.0 * self.reach[moving]]),
                               np.concatenate([b.yaw[obj], b.yaw[moving]]))
        self.table: npt.NDArray[np.float64] = np.full((len(rays.range_m), len(b)), np.inf)
        self.table[:, obj] = both[:, :obj.size]
        self.near = [np.zeros(0, np.int64)] * len(b)
        for k, i in enumerate(moving):
            self.near[i] = np.flatnonzero(np.isfinite(both[:, obj.size + k]))
        self.ev = self._evidence(b)
        self.prior_cache: dict[bytes, float] = {}
        self.expected = self._expected(present, slice(None))
        self.ll = ray_log_likelihoods(rays, self.expected, settings.likelihood)
        self.prior_value = self.prior(present)

    def snapshot(self) -> _Snapshot:
        """The state, to return to the best scene seen without recomputing."""
        return _Snapshot(self.boxes, self.present.copy(), self.ev, self.table.copy(), self.expected.copy(),
                         self.ll.copy(), self.prior_value)

    def restore(self, state: _Snapshot) -> None:
        self.boxes, self.present, self.ev, self.table, self.expected, self.ll, self.prior_value = state
        self.prior_cache = {}

    def _evidence(self, boxes: Boxes) -> Evidence:
        c = self.s.context
        return evidence_predicates(boxes, k_sigma=c.k_sigma, min_tolerance_m=c.min_tolerance_m,
                                   stable_margin_m=c.stable_margin_m)

    def _expected(self, present: npt.NDArray[np.bool_], rows: slice | npt.NDArray[np.int64]) -> npt.NDArray[np.float64]:
        t = self.table[rows][:, present]
        expected: npt.NDArray[np.float64] = np.minimum(self.fixed_min[rows], t.min(axis=1, initial=np.inf))
        return expected

    def prior(self, present: npt.NDArray[np.bool_], ev: Evidence | None = None, boxes: Boxes | None = None) -> float:
        if ev is not None:
            return log_prior(boxes or self.boxes, ev, present, self.space.added, self.s.context)
        key = present.tobytes()
        value = self.prior_cache.get(key)
        if value is None:
            value = self.prior_cache[key] = log_prior(self.boxes, self.ev, present, self.space.added, self.s.context)
        return value

    def detector_term(self) -> float:
        z = (self.boxes.centre - self.space.origin_centre) / np.maximum(self.boxes.sigma, 1e-6)
        return -0.5 * self.s.detector_weight * float((z[self.detected] ** 2).sum())

    def score(self) -> float:
        if self.prior_value == -math.inf:
            return -math.inf
        return self.prior_value + self.s.likelihood.ray_weight * float(self.ll.sum()) + self.detector_term()

    def flip(self, unit: npt.NDArray[np.int64], rng: np.random.Generator | None, *, greedy: bool = False) -> float:
        """Propose setting ``unit`` to the opposite of its first box; Metropolis-accept with ``rng``, or accept only
        a gain when ``greedy`` (rng None and not greedy: only return the ratio, changing nothing).

        Returns the log posterior ratio, new over old."""
        trial = self.present.copy()
        trial[unit] = ~trial[unit[0]]
        new_prior = self.prior(trial)
        rows = np.flatnonzero(np.isfinite(self.table[:, unit]).any(axis=1))
        expected = self._expected(trial, rows)
        ll = ray_log_likelihoods(self.rays._replace(range_m=self.rays.range_m[rows],
                                                    background=self.rays.background[rows]),
                                 expected, self.s.likelihood)
        d_lik = self.s.likelihood.ray_weight * float((ll - self.ll[rows]).sum())
        if new_prior == -math.inf:
            ratio = -math.inf
        elif self.prior_value == -math.inf:
            ratio = math.inf
        else:
            ratio = new_prior - self.prior_value + d_lik
        if greedy:
            accept = ratio > 1e-9
        else:
            accept = rng is not None and ratio > -math.inf and (ratio >= 0.0 or rng.random() < math.exp(ratio))
        if accept:
            self.present, self.prior_value = trial, new_prior
            self.expected[rows], self.ll[rows] = expected, ll
        return ratio

    def pose_move(self, i: int, rng: np.random.Generator) -> bool:
        """Eqs. 4.5-4.7 for object i: n Gaussian corrections weighted by the sensor model; True if accepted."""
        n = self.s.pose_proposals
        b = self.boxes
        origin = self.space.origin_centre[i]
        steps = rng.normal(0.0, 1.0, (n, 3)) * (self.s.pose_step_sigma * np.maximum(b.sigma[i], 1e-3))
        lo, hi = self.start[i] - self.reach[i], self.start[i] + self.reach[i]
        cand = np.vstack([b.centre[i:i + 1], np.clip(b.centre[i] + steps, lo, hi)])  # row 0: e_{t,0}
        rows = self.near[i]
        sub = self.rays._replace(origin=self.rays.origin[rows], direction=self.rays.direction[rows],
                                 range_m=self.rays.range_m[rows], background=self.rays.background[rows])
        cols = entry_distances(sub, cand, np.repeat(b.size[i:i + 1], n + 1, 0), np.repeat(b.yaw[i], n + 1))
        others = self.present.copy()
        others[i] = False
        base = self._expected(others, rows)
        expected = np.minimum(base[None, :], cols.T)  # (n + 1, rows)
        weight = self.s.likelihood.ray_weight * ray_log_likelihoods(sub, expected, self.s.likelihood).sum(axis=1)
        if self.detected[i]:
            z = (cand - origin) / np.maximum(b.sigma[i], 1e-6)
            weight = weight - 0.5 * self.s.detector_weight * (z ** 2).sum(axis=1)
        best = int(np.argmax(weight[1:])) + 1
        centre = b.centre.copy()
        centre[i] = cand[best]
        moved = Boxes(centre=centre, half=b.half, size=b.size, yaw=b.yaw, sigma=b.sigma, kind=b.kind,
                      level=b.level, score=b.score)
        c = self.s.context
        ev = moved_evidence(self.ev, moved, i, k_sigma=c.k_sigma, min_tolerance_m=c.min_tolerance_m,
                            stable_margin_m=c.stable_margin_m)
        if same_evidence(ev, self.ev):
            ev, new_prior = self.ev, self.prior_value
        else:
            new_prior = self.prior(self.present, ev, moved)
        # P(M'|D) Q(M|M') / (P(M|D) Q(M'|M)) with Q from the sensor-model weights: the data terms cancel and the
        # prior ratio is left.
        if new_prior == -math.inf:
            return False
        log_ratio = new_prior - self.prior_value if self.prior_value > -math.inf else 0.0
        if log_ratio >= 0.0 or rng.random() < math.exp(log_ratio):
            if ev is not self.ev:
                self.prior_cache = {}
            self.boxes, self.ev, self.prior_value = moved, ev, new_prior
            self.table[rows, i] = cols[:, best]
            self.expected[rows] = expected[best]
            self.ll[rows] = ray_log_likelihoods(sub, expected[best], self.s.likelihood)
            return True
        return False


def infer_scene(
    bay: Bay, estimates: list[BoxEstimate], evidence: list[DepthEvidence], settings: InferenceSettings | None = None,
) -> SceneGraph:
    """The scene graph of one bay from its box estimates and depth views (see :func:`infer_bay_scene`)."""
    return infer_bay_scene(bay, estimates, evidence, settings).graph


def infer_bay_scene(
    bay: Bay, estimates: list[BoxEstimate], evidence: list[DepthEvidence], settings: InferenceSettings | None = None,
) -> SceneInference:
    """The scene graph of one bay, the estimates skipped (with reasons) and the scene's log posterior.

    Parameters
    ----------
    bay
        The rack model's bay (levels, bins).
    estimates
        Box estimates of the bay's pallets and loads (beams come from the rack model; bad estimates are
        skipped with a reason).
    evidence
        Depth views of the bay (may be empty: then the context and the detector decide alone).
    settings
        Rules, likelihood and chain settings; defaults when None.

    Returns
    -------
    SceneInference
        The graph: supports (kind beam; level 0 is the floor), detections (``false_estimate`` when the scene
        leaves them out) and added hidden objects (``hidden_below``), ``supports`` and ``unstable_contact``
        edges, node and edge probabilities.

    Raises
    ------
    SceneError
        When the bay has no usable rack model (no levels, levels out of order), a depth view is malformed,
        more than ``max_objects`` estimates remain or more than 16 of them intersect one another.
    """
    s = settings or InferenceSettings()
    validate_bay(bay)
    detections, kept, skipped = usable_estimates(bay, estimates)
    if len(kept) > s.max_objects:
        raise SceneError(f"bay {bay.key!r} has {len(kept)} estimates, more than max_objects={s.max_objects}")
    base = concat(supports(bay), detections)
    estimated = base.centre.copy()
    base = _snap_down(base, s)
    ctx = infer_context(base, s.context)
    space = _hypothesis_space(bay, base, ctx, s)
    space = space._replace(origin_centre=np.concatenate([estimated, space.origin_centre[len(base):]]))
    rays = prepare_rays(bay, evidence, s.likelihood)
    beam_c, beam_h = beam_boxes(bay)
    fixed = entry_distances(rays, beam_c, 2.0 * beam_h, np.zeros(len(beam_c)))
    fixed_min = fixed.min(axis=1) if fixed.shape[1] else np.full(fixed.shape[0], np.inf)
    n_base = len(base)
    present = np.ones(len(space.boxes), bool)
    present[:n_base] = ctx.p_false < 0.5
    for unit, carrier in zip(space.units, space.carriers, strict=True):
        if carrier >= 0:
            present[unit] = ctx.p_hidden[carrier] > 0.5 and bool(present[carrier])
    present = _feasible(space, present, s)
    chain = _Chain(space, rays, fixed_min, s, present)
    rng = np.random.default_rng(s.seed)
    start = time.process_time()
    score = chain.score()
    best, best_score = chain.snapshot(), score
    sweeps = 0
    while sweeps < s.max_sweeps:
        sweeps += 1
        before = chain.present.copy()
        for i in np.flatnonzero(chain.present & (space.boxes.kind != SUPPORT)) if sweeps <= s.pose_sweeps else ():
            if chain.near[i].size:
                chain.pose_move(int(i), rng)
        for unit in _flip_proposals(space, rng):
            chain.flip(unit, rng)
        score = chain.score()
        improved = score - best_score
        if score > best_score:
            best, best_score = chain.snapshot(), score
        flips = int((chain.present != before).sum())
        if time.process_time() - start > s.time_budget_s or (
                sweeps >= s.min_sweeps and flips == 0 and improved < s.converged_log):
            break
    if score < best_score:
        chain.restore(best)
    for _ in range(s.max_sweeps):  # finish at the mode: flips that raise the posterior, until none does
        if sum(chain.flip(unit, None, greedy=True) > 1e-9 for unit in _flip_proposals(space, rng)) == 0:
            break
    best_score = chain.score()
    stamp = max([e.stamp_ns for e in kept] + [v.stamp_ns for v in evidence], default=0)
    graph = _graph(bay, kept, chain, n_base, sweeps, stamp)
    return SceneInference(graph=graph, skipped=skipped, log_posterior=best_score)


def _feasible(space: _Space, present: npt.NDArray[np.bool_], s: InferenceSettings) -> npt.NDArray[np.bool_]:
    """Leave out, until the hard rules hold, what breaks them: loads and pallets without their kind of base, the
    weaker of two intersecting objects, added objects that carry nothing (a start the chain can move from)."""
    c = s.context
    b = space.boxes
    ev = evidence_predicates(b, k_sigma=c.k_sigma, min_tolerance_m=c.min_tolerance_m,
                             stable_margin_m=c.stable_margin_m)
    present = present.copy()
    obj = b.kind != SUPPORT
    for _ in range(len(b)):
        if log_prior(b, ev, present, space.added, c) > -math.inf:
            break
        terms = object_terms(b, ev, present)
        live = present & obj
        drop = (terms.needs_below | terms.must_be_false) & live
        order = np.lexsort((np.arange(len(b)), b.score))  # weaker first; ties: the earlier box
        rank = np.empty(len(b), np.int64)
        rank[order] = np.arange(len(b))
        clash = ev.intersect & live[:, None] & live[None, :] & (rank[:, None] < rank[None, :])
        drop |= clash.any(axis=1)
        drop |= space.added & present & ~(ev.rests_on & present[:, None]).any(axis=0)
        present &= ~drop
    return present


def _flip_proposals(space: _Space, rng: np.random.Generator) -> list[npt.NDArray[np.int64]]:
    """One sweep's flips in random order: every unit alone, and every candidate with the detection it is under
    (a ghost and the hidden object below it go together); each sets its boxes to the opposite of the first's."""
    flips = list(space.units)
    flips += [np.concatenate([[c], u]) for u, c in zip(space.units, space.carriers, strict=True) if c >= 0]
    return [flips[k] for k in rng.permutation(len(flips))]


def _snap_down(base: Boxes, s: InferenceSettings) -> Boxes:
    """Data-driven pose correction before the chain: a load or pallet a little above the right kind of base (at most
    ``snap_m``, beyond the contact tolerance) is lowered onto it; the detector term still pulls it back."""
    c = s.context
    ev = evidence_predicates(base, k_sigma=c.k_sigma, min_tolerance_m=c.min_tolerance_m)
    terms = object_terms(base, ev)
    centre = base.centre.copy()
    ok = allowed_base(base.kind)
    lo, hi = base.centre[:, :2] - base.half[:, :2], base.centre[:, :2] + base.half[:, :2]
    for i in np.flatnonzero(terms.needs_below | terms.must_be_false):
        under = (lo < hi[i]).all(axis=1) & (hi > lo[i]).all(axis=1) & (base.top <= base.bottom[i] + 0.01)
        under[i] = False
        if not under.any():
            continue
        j = int(np.flatnonzero(under)[np.argmax(base.top[under])])
        gap = float(base.bottom[i] - base.top[j])
        if ok[i, j] and 0.0 < gap <= s.snap_m:
            centre[i, 2] -= gap
    return dataclasses.replace(base, centre=centre)


def _hypothesis_space(bay: Bay, base: Boxes, ctx: ContextResult, s: InferenceSettings) -> _Space:
    """Add candidate hidden objects under loads that rest on no pallet or load."""
    terms = object_terms(base, ctx.evidence)
    n = len(base)
    units = [np.array([i], np.int64) for i in range(n) if base.kind[i] != SUPPORT]
    carriers = [-1] * len(units)
    extra: list[Boxes] = []
    c = s.context
    lo, hi = base.centre[:, :2] - base.half[:, :2], base.centre[:, :2] + base.half[:, :2]
    for i in np.flatnonzero(terms.needs_below):
        tol = np.maximum(c.k_sigma * np.hypot(base.sigma[i, 2], base.sigma[:, 2]), c.min_tolerance_m)
        under = (lo < hi[i]).all(axis=1) & (hi > lo[i]).all(axis=1) & (base.top <= base.bottom[i] + tol)
        under[i] = False
        if not under.any():
            continue
        j = int(np.flatnonzero(under)[np.argmax(base.top[under])])
        floor_z, gap = float(base.top[j]), float(base.bottom[i] - base.top[j])
        if gap < (0.5 * s.pallet_height_m if base.kind[j] == SUPPORT else s.min_hidden_height_m):
            continue
        if base.kind[j] == SUPPORT:
            pallet_h = gap if gap <= s.max_pallet_height_m else s.pallet_height_m
            parts = [(PALLET, floor_z, pallet_h)]
            if gap > s.max_pallet_height_m:
                parts.append((LOAD, floor_z + pallet_h, gap - pallet_h))
            footprint = int(i)
        else:
            parts = [(LOAD, floor_z, gap)]
            # goods on a pallet are smaller than it: the carrier's footprint; a carton missed inside a stack has
            # the stack's (the one below), also under an overhanging carton
            footprint = j if base.kind[j] == LOAD else int(i)
        first = n + sum(len(b) for b in extra)
        extra.append(_boxes_under(bay, base, footprint, parts, s.pallet_footprint_m))
        units.append(np.arange(first, first + len(parts), dtype=np.int64))
        carriers.append(int(i))
    boxes = concat(base, *extra) if extra else base
    added = np.zeros(len(boxes), bool)
    added[n:] = True
    return _Space(boxes=boxes, added=added, units=units, carriers=carriers, origin_centre=boxes.centre.copy())


def _boxes_under(bay: Bay, base: Boxes, i: int, parts: list[tuple[int, float, float]],
                 pallet_m: tuple[float, float]) -> Boxes:
    """Boxes of ``parts`` (kind, bottom z, height) with box i's footprint (the carrier's over a support or a pallet,
    the base's inside a stack), at least a pallet's for a pallet (then axis-aligned with the bay)."""
    m = len(parts)
    kind = np.array([k for k, _, _ in parts], np.int64)
    size = np.column_stack([np.repeat(base.size[i:i + 1, :2], m, 0), [h for _, _, h in parts]])
    yaw = np.repeat(base.yaw[i], m)
    half = hull_half(size, yaw)
    pallet = kind == PALLET
    half[pallet, :2] = np.maximum(half[pallet, :2], 0.5 * np.array(pallet_m))
    size[pallet, :2] = 2.0 * half[pallet, :2]
    yaw[pallet] = 0.0
    centre = np.column_stack([np.repeat(base.centre[i:i + 1, :2], m, 0), [z + 0.5 * h for _, z, h in parts]])
    bottom = np.array([z for _, z, _ in parts])
    return Boxes(centre=centre, half=half, size=size, yaw=yaw, sigma=np.repeat(base.sigma[i:i + 1], m, 0),
                 kind=kind, level=levels_of(bay, bottom), score=np.ones(m))


def _graph(bay: Bay, kept: list[BoxEstimate], chain: _Chain, n_base: int, sweeps: int, stamp: int) -> SceneGraph:
    """The chain's best scene as a graph in the map frame, with Gibbs presence probabilities."""
    b, present, space = chain.boxes, chain.present, chain.space
    prob = np.ones(len(b))
    for unit in space.units:
        ratio = chain.flip(unit, None)  # log odds of the flipped state against the present one
        odds = -ratio if present[unit[0]] else ratio
        prob[unit] = 1.0 / (1.0 + math.exp(-min(max(odds, -50.0), 50.0)))
    n_sup = int((b.kind[:n_base] == SUPPORT).sum())
    centre_map = to_map_frame(bay, b.centre)
    yaw_map = yaw_to_map(bay, b.yaw)
    ids: list[str] = []
    nodes: list[SceneNode] = []
    hidden_n = 0
    for i in range(len(b)):
        if i < n_sup:
            node_id = f"{bay.key}/floor" if bay.levels_z_m[i] <= 0.0 else f"{bay.key}/beams{i}"
            flags: frozenset[Flag] = frozenset()
        elif i < n_base:
            node_id = kept[i - n_sup].id
            flags = frozenset() if present[i] else frozenset({Flag.FALSE_ESTIMATE})
        elif present[i]:
            hidden_n += 1
            node_id = f"{bay.key}/hidden{hidden_n}"
            flags = frozenset({Flag.HIDDEN_BELOW})
        else:
            ids.append("")
            continue
        ids.append(node_id)
        c = centre_map[i]
        nodes.append(SceneNode(id=node_id, kind=CODE_KIND[int(b.kind[i])],
                               centre=(float(c[0]), float(c[1]), float(c[2])),
                               size=(float(b.size[i, 0]), float(b.size[i, 1]), float(b.size[i, 2])),
                               yaw_rad=float(yaw_map[i]),
                               level=int(b.level[i]) if b.level[i] >= 0 else None, flags=flags,
                               probability=float(prob[i])))
    terms = object_terms(b, chain.ev, present)
    sup, unstable = support_relations(chain.ev.contact, chain.ev.rests_on, terms.stable, present)
    edges = [SceneEdge(ids[j], ids[i], Relation.SUPPORTS, float(prob[i] * prob[j]))
             for j, i in zip(*np.nonzero(sup), strict=True)]
    edges += [SceneEdge(ids[i], ids[j], Relation.UNSTABLE_CONTACT, float(prob[i] * prob[j]))
              for i, j in zip(*np.nonzero(np.triu(unstable)), strict=True)]
    return SceneGraph(bay=bay.key, nodes=tuple(nodes), edges=tuple(edges), stamp_ns=stamp, iterations=sweeps)
