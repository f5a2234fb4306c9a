"""Regions joined where another stage's floor plan says they are one room (the floor plan's room parts).

The floor-plan stage (:mod:`services.floor_plan`) explains a map as rectangular units and cuts each unit's free
space at the walls it stands over into **parts** (:func:`~services.floor_plan.pipeline.part_cells`): a part is
a piece of one room with no wall across it. On a real map the decomposition often cuts one room into pieces
along laser rays and clutter (no wall between them); two touching regions that both lie mostly in one part are
one room. A part the plan stretched over several rooms (walls it did not see: slanted walls explained in steps)
would join those rooms, so a join also needs the two regions to cover a good share of the part.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from services.grid_decomposition.errors import DecompositionError


def join_in_parts(
    segments: npt.NDArray[np.int32], parts: npt.NDArray[np.integer], *, min_share: float = 0.5,
    min_cover: float = 0.5, keep: npt.NDArray[np.bool_] | None = None,
) -> npt.NDArray[np.int32]:
    """Join touching regions that lie mostly in the same part of a floor plan.

    Two regions that share a border (4-neighbouring pixels) are joined when both have at least ``min_share``
    of their pixels in the same part and together they cover at least ``min_cover`` of that part; the joins
    chain (three pieces of one part become one region).

    Parameters
    ----------
    segments : (H, W) int32
        Region id per pixel, 0 where no region.
    parts : (H, W) integer
        Part id per pixel (:func:`~services.floor_plan.pipeline.part_cells`), 0 where none.
    min_share, min_cover : float
        Shares in (0, 1].
    keep : (H, W) bool, optional
        Regions with a pixel here are never joined (racks, aisles, warehouse floors).

    Returns
    -------
    (H, W) int32
        The regions, each joined group under its smallest id.

    Raises
    ------
    DecompositionError
        Parts of another shape than the segments; shares outside (0, 1].
    """
    if parts.shape != segments.shape:
        raise DecompositionError(f"floor-plan parts of shape {parts.shape} on a grid of {segments.shape}")
    if not (0 < min_share <= 1 and 0 <= min_cover <= 1):
        raise DecompositionError(f"shares must be in (0, 1], got {min_share} and {min_cover}")
    n = int(segments.max()) + 1
    m = int(parts.max()) + 1
    if n < 3 or m < 2:
        return segments
    both = (segments > 0) & (parts > 0)
    joint = np.bincount(segments[both].astype(np.int64) * m + parts[both], minlength=n * m).reshape(n, m)
    size = np.bincount(segments.ravel(), minlength=n)
    part = joint.argmax(axis=1)
    inside = joint[np.arange(n), part]
    mostly = (inside >= min_share * np.maximum(size, 1)) & (inside > 0)
    mostly[0] = False
    if keep is not None:
        mostly[np.unique(segments[keep])] = False
    a = np.concatenate([segments[:, :-1].ravel(), segments[:-1, :].ravel()])
    b = np.concatenate([segments[:, 1:].ravel(), segments[1:, :].ravel()])
    touching = (a != b) & mostly[a] & mostly[b]
    pairs = np.unique(np.minimum(a[touching], b[touching]).astype(np.int64) * n + np.maximum(a[touching], b[touching]))
    p, q = pairs // n, pairs % n
    part_size = np.bincount(parts.ravel(), minlength=m)
    ok = (part[p] == part[q]) & (inside[p] + inside[q] >= min_cover * part_size[part[p]])
    if not ok.any():
        return segments
    graph = coo_matrix((np.ones(int(ok.sum())), (p[ok], q[ok])), shape=(n, n))
    _, group = connected_components(graph, directed=False)
    first = np.full(int(group.max()) + 1, n, dtype=np.int64)
    np.minimum.at(first, group, np.arange(n))
    lut = first[group].astype(np.int32)
    lut[0] = 0
    return np.take(lut, segments)
