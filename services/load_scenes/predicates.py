"""Evidence predicates of seed 003 table 4.1 for a rack bay, computed from box geometry over all pairs at once.

The seed tests oriented boxes for touching vertices, edges or faces. Rack objects stand upright (a yaw only),
so the pair tests here work on the boxes' hulls in the bay frame, axis by axis: the signed gap between two
boxes along an axis is ``|c_i - c_j| - (h_i + h_j)``, and the tolerance along it is ``k_sigma`` standard
deviations of the difference of the two centres (at least ``min_tolerance_m``). Measured in tolerances, the
largest of the three gaps says how the boxes meet: below -1 they interpenetrate along every axis
(``intersect``), within [-1, 1] they touch (``contact``), above 1 they are apart.

``higher(i, j)`` is the rack reading of the seed's "higher": i's bottom is not below j's top (within
tolerance); with a contact and overlapping footprints it means i rests on j (``rests_on``). ``hover(i)`` is the
seed's: no contact or intersection with anything, supports included. ``stable(i)`` replaces the seed's upright
test (every box here is upright): i's centre of mass lies over the top faces of what it rests on, so an
overhanging or leaning load is unstable; the supports (the seed's table) are stable (r9).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import numpy.typing as npt

from services.load_scenes.boxes import SUPPORT, Boxes

Mask = npt.NDArray[np.bool_]


class Evidence(NamedTuple):
    """The evidence predicates of K boxes (pair arrays are (K, K), ``[i, j]`` about i and j; diagonals False)."""

    contact: Mask
    intersect: Mask
    higher: Mask
    rests_on: Mask
    """``[i, j]``: i stands on j (contact, i higher than j, footprints overlap)."""
    hover: Mask
    stable: Mask


def pair_gaps(boxes: Boxes, *, k_sigma: float, min_tolerance_m: float) -> npt.NDArray[np.float64]:
    """Signed gaps between all pairs along u, v, z in units of their tolerance, (K, K, 3).

    Examples
    --------
    Two 1 m cubes side by side 1 cm apart touch within a 2 cm tolerance:

    >>> import numpy as np
    >>> from services.load_scenes.boxes import Boxes, LOAD
    >>> b = Boxes(centre=np.array([[0.0, 0, 0.5], [1.01, 0, 0.5]]), half=np.full((2, 3), 0.5),
    ...           size=np.ones((2, 3)), yaw=np.zeros(2), sigma=np.zeros((2, 3)), kind=np.full(2, LOAD),
    ...           level=np.zeros(2, np.int64), score=np.ones(2))
    >>> float(pair_gaps(b, k_sigma=3.0, min_tolerance_m=0.02)[0, 1].max())
    0.5
    """
    gap = np.abs(boxes.centre[:, None, :] - boxes.centre[None, :, :]) - (boxes.half[:, None, :] + boxes.half[None])
    tol = np.maximum(k_sigma * np.hypot(boxes.sigma[:, None, :], boxes.sigma[None, :, :]), min_tolerance_m)
    gaps: npt.NDArray[np.float64] = gap / tol
    return gaps


def evidence_predicates(
    boxes: Boxes, *, k_sigma: float = 3.0, min_tolerance_m: float = 0.02, stable_margin_m: float = 0.0,
) -> Evidence:
    """Table 4.1's predicates for all boxes of a bay.

    Parameters
    ----------
    boxes
        The bay's supports and objects in the bay frame.
    k_sigma
        Tolerance of contact and intersection in standard deviations of the two centres' difference.
    min_tolerance_m
        Least tolerance, metres (what two exactly known boxes may be apart and still touch).
    stable_margin_m
        How far a centre of mass may lie beyond the supporting top faces and still count as stable, metres.

    Returns
    -------
    Evidence
        Pair predicates (K, K) and object predicates (K,), booleans.
    """
    k = len(boxes)
    gaps = pair_gaps(boxes, k_sigma=k_sigma, min_tolerance_m=min_tolerance_m)
    worst = gaps.max(axis=2)
    off_diagonal = ~np.eye(k, dtype=bool)
    intersect = (worst < -1.0) & off_diagonal
    contact = (worst >= -1.0) & (worst <= 1.0) & off_diagonal
    tol_z = np.maximum(k_sigma * np.hypot(boxes.sigma[:, None, 2], boxes.sigma[None, :, 2]), min_tolerance_m)
    higher = (boxes.bottom[:, None] >= boxes.top[None, :] - tol_z) & off_diagonal
    footprint_overlap = (gaps[:, :, 0] < 0.0) & (gaps[:, :, 1] < 0.0)
    rests_on = contact & higher & footprint_overlap
    hover = ~(contact | intersect).any(axis=1) & (boxes.kind != SUPPORT)
    return Evidence(contact=contact, intersect=intersect, higher=higher, rests_on=rests_on, hover=hover,
                    stable=stable(boxes, rests_on, margin_m=stable_margin_m))


def moved_evidence(
    ev: Evidence, boxes: Boxes, i: int, *, k_sigma: float = 3.0, min_tolerance_m: float = 0.02,
    stable_margin_m: float = 0.0,
) -> Evidence:
    """The evidence after box i moved (``boxes`` hold its new pose): row and column i recomputed, (K,) rebuilt.

    Same result as :func:`evidence_predicates` on ``boxes``, at the cost of one row (the MCMC moves one box at a
    time).
    """
    c, h, sg = boxes.centre, boxes.half, boxes.sigma
    gap = (np.abs(c[i] - c) - (h[i] + h)) / np.maximum(k_sigma * np.hypot(sg[i], sg), min_tolerance_m)  # (K, 3)
    worst = gap.max(axis=1)
    worst[i] = np.inf
    tol_z = np.maximum(k_sigma * np.hypot(sg[i, 2], sg[:, 2]), min_tolerance_m)
    bottom, top = boxes.bottom, boxes.top
    overlap = (gap[:, 0] < 0.0) & (gap[:, 1] < 0.0)
    contact_i = (worst >= -1.0) & (worst <= 1.0)
    above_i = bottom[i] >= top - tol_z  # i higher than j
    below_i = bottom >= top[i] - tol_z  # j higher than i
    above_i[i] = below_i[i] = False
    contact, intersect = ev.contact.copy(), ev.intersect.copy()
    higher, rests_on = ev.higher.copy(), ev.rests_on.copy()
    contact[i], contact[:, i] = contact_i, contact_i
    intersect[i] = intersect[:, i] = worst < -1.0
    higher[i], higher[:, i] = above_i, below_i
    rests_on[i], rests_on[:, i] = contact_i & above_i & overlap, contact_i & below_i & overlap
    hover = ~(contact | intersect).any(axis=1) & (boxes.kind != SUPPORT)
    return Evidence(contact=contact, intersect=intersect, higher=higher, rests_on=rests_on, hover=hover,
                    stable=stable(boxes, rests_on, margin_m=stable_margin_m))


def same_evidence(a: Evidence, b: Evidence) -> bool:
    """Whether two evidence sets agree on every predicate."""
    return all(np.array_equal(x, y) for x, y in zip(a, b, strict=True))


def stable(boxes: Boxes, rests_on: Mask, *, margin_m: float = 0.0) -> Mask:
    """Whether each box's centre of mass (u, v) lies over the hull of the top faces it rests on, (K,) bool.

    Supports are stable; a box resting on nothing is upright, hence stable in the seed's sense (its
    problem is ``hover``, not its pose).
    """
    lo = np.where(rests_on[:, :, None], boxes.centre[None, :, :2] - boxes.half[None, :, :2], np.inf).min(axis=1)
    hi = np.where(rests_on[:, :, None], boxes.centre[None, :, :2] + boxes.half[None, :, :2], -np.inf).max(axis=1)
    c = boxes.centre[:, :2]
    over = ((c >= lo - margin_m) & (c <= hi + margin_m)).all(axis=1)
    result: Mask = over | ~rests_on.any(axis=1) | (boxes.kind == SUPPORT)
    return result


def support_relations(
    contact: Mask, rests_on: Mask, is_stable: Mask, present: Mask | None = None,
) -> tuple[Mask, Mask]:
    """Rule r10 and its complement: ``supports[j, i]`` (j stably holds i) and ``unstable[i, j]`` (symmetric).

    ``supports[j, i]`` holds when i rests on j and both are stable. Two boxes in contact have an unstable
    contact when neither supports the other and at least one of them is unstable (a leaning or overhanging
    load); side contacts of stable boxes are no relation. Only boxes in ``present`` take part.
    """
    keep = np.ones(contact.shape[0], bool) if present is None else present
    pair = keep[:, None] & keep[None, :]
    both_stable = is_stable[:, None] & is_stable[None, :]
    supports: Mask = (rests_on & pair & both_stable).T
    unstable: Mask = contact & pair & ~(supports | supports.T) & ~both_stable
    return supports, unstable
