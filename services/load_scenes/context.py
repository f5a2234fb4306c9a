"""Context knowledge (seed 003 table 4.3) adapted to rack bays: hard rules, soft rules in log-odds, exact inference.

Constants are a bay's supports (a beam pair per level, the floor at level 0: the seed's table) and its
objects. Query atoms per object: ``false(o)`` (a false estimate) and ``hidden(o)`` (an undetected object under
o). ``supported``/``supportive`` are what hard rule r10 derives from the evidence (closed world: nothing else
makes them true). Rules, with the seed's numbering:

* r1-r6 hold by construction of the predicates (irreflexive, symmetric contact/intersect, antisymmetric
  higher); r7-r9: supports are never false or hidden and always stable (they come from the rack model).
* r10 (hard): stable(o1) ∧ stable(o2) ∧ rests_on(o1, o2) → supports(o2, o1).
* r13 (hard here, 0.9 in the seed): an object that rests on nothing of the right kind is false or has a
  hidden object below: a load must rest on a pallet or a load, a pallet on its level's beam pair or the floor.
  A pallet not on a beam pair or the floor cannot be fixed by something hidden: it is false.
* r14 (hard here, 0.9 in the seed): of two intersecting objects at least one is false.
* hidden(o) → !false(o) (hard, added): a ghost hides nothing.
* r11 supported → !hidden (0.7), r12 !stable → !supportive (0.9), r15 supportive → !false (0.7),
  r16 stable → !false (0.9), with the seed's weights.
* Added: the detector's score as log-odds for !false (``score_weight``·logit(score)), and a base rate of
  hidden objects (``hidden_log_odds``) so that a hidden object is not added for free.

Inference is exact: given the evidence only r14 ties atoms of two objects, so the ground network falls
apart into the components of the intersection graph; each component's 2^k assignments of its false atoms
are enumerated (hidden atoms summed out per object). For the MCMC, :func:`log_prior` scores one world.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
import numpy.typing as npt
from pydantic import BaseModel, Field
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import connected_components

from services.load_scenes.boxes import LOAD, PALLET, SUPPORT, Boxes
from services.load_scenes.errors import SceneError
from services.load_scenes.predicates import Evidence, Mask, evidence_predicates, stable, support_relations

VERY_SURE = math.log(0.9 / 0.1)
RELATIVELY_SURE = math.log(0.7 / 0.3)
MAX_COMPONENT = 16
"""Most objects tied by intersections that exact inference enumerates (2^16 worlds)."""


class ContextSettings(BaseModel):
    """Weights of the soft rules in log-odds, and the predicates' tolerances."""

    supported_not_hidden: float = Field(RELATIVELY_SURE, ge=0.0, description="r11")
    unstable_not_supportive: float = Field(VERY_SURE, ge=0.0, description="r12")
    supportive_not_false: float = Field(RELATIVELY_SURE, ge=0.0, description="r15")
    stable_not_false: float = Field(VERY_SURE, ge=0.0, description="r16")
    score_weight: float = Field(1.0, ge=0.0, description="Multiplies logit(score) as log-odds of !false.")
    hidden_log_odds: float = Field(math.log(0.3 / 0.7), le=0.0, description="Base rate of a hidden object.")
    k_sigma: float = Field(3.0, gt=0.0, description="Contact/intersect tolerance in standard deviations.")
    min_tolerance_m: float = Field(0.02, gt=0.0)
    stable_margin_m: float = Field(0.0, ge=0.0, description="How far a centre of mass may overhang.")


class ObjectTerms(NamedTuple):
    """What the rules need of each box, from the evidence (K,) booleans."""

    stable: Mask
    supported: Mask
    supportive: Mask
    needs_below: Mask
    """A load resting on no pallet or load (r13 as adapted: false, or something hidden below)."""
    must_be_false: Mask
    """A pallet resting on no beam pair or floor: no hidden object fixes that."""


class ContextResult(NamedTuple):
    """Exact marginals and the relations of a bay's detected boxes."""

    evidence: Evidence
    p_false: npt.NDArray[np.float64]
    """(K,) probability of false(o) (0 for supports)."""
    p_hidden: npt.NDArray[np.float64]
    """(K,) probability of hidden(o)."""
    supports: Mask
    """(K, K) ``[j, i]``: j stably holds i."""
    unstable: Mask
    """(K, K) symmetric unstable contacts."""


def allowed_base(kind: npt.NDArray[np.int64]) -> Mask:
    """``[i, j]``: j is the right kind of thing for i to rest on (a load on a pallet or load, a pallet on a support)."""
    load_on = (kind[:, None] == LOAD) & ((kind[None, :] == PALLET) | (kind[None, :] == LOAD))
    pallet_on = (kind[:, None] == PALLET) & (kind[None, :] == SUPPORT)
    result: Mask = load_on | pallet_on
    return result


def object_terms(boxes: Boxes, ev: Evidence, present: Mask | None = None) -> ObjectTerms:
    """The evidence terms of every box given which boxes are there (``present``; all when None)."""
    k = len(boxes)
    keep = np.ones(k, bool) if present is None else present
    rests = ev.rests_on & keep[None, :]
    st = stable(boxes, rests) if present is not None else ev.stable
    supports, _ = support_relations(ev.contact, ev.rests_on, st, keep)
    obj = boxes.kind != SUPPORT
    good = (rests & allowed_base(boxes.kind)).any(axis=1)
    supported: Mask = supports.sum(axis=0) > 0
    supportive: Mask = supports.sum(axis=1) > 0
    return ObjectTerms(stable=st, supported=supported, supportive=supportive,
                       needs_below=obj & ~good & (boxes.kind == LOAD), must_be_false=~good & (boxes.kind == PALLET))


def _unary_log_weights(boxes: Boxes, terms: ObjectTerms, s: ContextSettings) -> npt.NDArray[np.float64]:
    """(K, 4) log-weights of the states (false, hidden) = (0,0), (0,1), (1,0), (1,1) of each object."""
    score = np.clip(boxes.score, 1e-3, 1.0 - 1e-3)
    keep = s.score_weight * np.log(score / (1.0 - score))
    lose = -(s.stable_not_false * terms.stable + s.supportive_not_false * terms.supportive)
    hid = s.hidden_log_odds - s.supported_not_hidden * terms.supported
    w = np.stack([keep, keep + hid, lose, np.full(len(boxes), -np.inf)], axis=1)
    w[terms.needs_below, 0] = -np.inf
    w[terms.must_be_false, :2] = -np.inf
    return w


def infer_context(boxes: Boxes, settings: ContextSettings) -> ContextResult:
    """Exact marginals of false(o) and hidden(o) for a bay's boxes, and the relations among them.

    Parameters
    ----------
    boxes
        Supports first, then the detected objects, in the bay frame.
    settings
        Rule weights and tolerances.

    Raises
    ------
    SceneError
        When more than ``MAX_COMPONENT`` objects intersect one another (no bay holds that many).
    """
    ev = evidence_predicates(boxes, k_sigma=settings.k_sigma, min_tolerance_m=settings.min_tolerance_m,
                             stable_margin_m=settings.stable_margin_m)
    terms = object_terms(boxes, ev)
    obj = np.flatnonzero(boxes.kind != SUPPORT)
    p_false = np.zeros(len(boxes))
    p_hidden = np.zeros(len(boxes))
    if obj.size:
        w = _unary_log_weights(boxes, terms, settings)[obj]
        alive = np.logaddexp(w[:, 0], w[:, 1])  # false atom 0, hidden summed out
        dead = np.logaddexp(w[:, 2], w[:, 3])
        inter = ev.intersect[np.ix_(obj, obj)]
        n, labels = connected_components(csr_matrix(inter), directed=False)
        for c in range(n):
            idx = np.flatnonzero(labels == c)
            if idx.size > MAX_COMPONENT:
                raise SceneError(f"{idx.size} objects intersect one another; at most {MAX_COMPONENT} are inferred")
            worlds = ((np.arange(2 ** idx.size)[:, None] >> np.arange(idx.size)) & 1).astype(bool)  # True: false
            logw = np.where(worlds, dead[idx], alive[idx]).sum(axis=1)
            sub = inter[np.ix_(idx, idx)]
            both_kept = ~worlds[:, :, None] & ~worlds[:, None, :] & sub[None]
            logw[both_kept.any(axis=(1, 2))] = -np.inf
            top = logw.max()
            if not np.isfinite(top):
                raise SceneError("the context rules admit no world for these boxes")
            pw = np.exp(logw - top)
            pw /= pw.sum()
            pf = pw @ worlds
            p_false[obj[idx]] = pf
            can_live = np.isfinite(alive[idx])
            ph_alive = np.exp(w[idx, 1] - np.where(can_live, alive[idx], 0.0))
            p_hidden[obj[idx]] = np.where(can_live, (1.0 - pf) * ph_alive, 0.0)
    supports, unstable = support_relations(ev.contact, ev.rests_on, ev.stable)
    return ContextResult(evidence=ev, p_false=p_false, p_hidden=p_hidden, supports=supports, unstable=unstable)


def log_prior(
    boxes: Boxes, ev: Evidence, present: Mask, added: Mask, settings: ContextSettings,
) -> float:
    """Unnormalised log prior (eq. 4.3) of one scene hypothesis: the objects ``present`` and which were ``added``.

    The world's atoms come from the hypothesis: false(o) is a detected box left out, hidden(o) an added box
    under a present one. Hard rules make the prior -inf: a present object resting on nothing of its kind's
    base, two present objects intersecting, an added object with nothing present on it.

    Parameters
    ----------
    boxes, ev
        All boxes of the hypothesis space (supports, detections, candidate hidden objects) and their evidence.
    present
        (K,) which boxes the hypothesis holds (supports always).
    added
        (K,) which boxes are candidate hidden objects rather than detections.
    """
    terms = object_terms(boxes, ev, present)
    obj = boxes.kind != SUPPORT
    live = present & obj
    if (terms.needs_below | terms.must_be_false)[live].any():
        return -math.inf
    if (ev.intersect & live[:, None] & live[None, :]).any():
        return -math.inf
    carried = (ev.rests_on & present[:, None]).any(axis=0)
    if (added & present & ~carried).any():
        return -math.inf
    s = settings
    detected = obj & ~added
    hidden = (ev.rests_on & (added & present)[None, :]).any(axis=1) & live
    supported_by_detected = (ev.rests_on & (present & ~added)[None, :]).any(axis=1)
    score = np.clip(boxes.score, 1e-3, 1.0 - 1e-3)
    keep = s.score_weight * np.log(score / (1.0 - score))
    total = float(keep[detected & present].sum())
    gone = detected & ~present
    would_support = (ev.rests_on & (present & terms.stable)[:, None]).any(axis=0) & terms.stable
    total -= float((s.stable_not_false * terms.stable + s.supportive_not_false * would_support)[gone].sum())
    total += s.hidden_log_odds * int((added & present).sum())
    total -= s.supported_not_hidden * int((hidden & supported_by_detected).sum())
    total -= s.unstable_not_supportive * int((live & ~terms.stable & terms.supportive).sum())
    return total
