"""Learned room joins: border features of touching room pieces and a small classifier over them."""

from __future__ import annotations

import json
from dataclasses import dataclass
from functools import cache
from pathlib import Path

import cv2
import numpy as np
import numpy.typing as npt
from scipy import ndimage

from services.grid_decomposition.basins import _near
from services.grid_decomposition.segments import renumber

MODEL_PATH = Path(__file__).with_name("data") / "join_model.json"

FEATURES = (
    "log_border_m",  # length of the shared border (pixel pairs), log metres
    "saddle_m",  # highest clearance along the border
    "saddle_min_peak",  # saddle over the smaller piece's peak clearance
    "saddle_max_peak",  # saddle over the larger piece's peak clearance
    "extent_min_width",  # border extent over the narrower piece's width (2 x its peak)
    "extent_max_width",  # border extent over the wider piece's width
    "extent_saddle",  # border extent over 2 x saddle (1: a door from wall to wall)
    "mean_clear_saddle",  # mean clearance along the border over the saddle
    "straightness",  # border extent over its length
    "furniture_share",  # share of the border with furniture within the reach
    "closed_share",  # share of the border on closed line pixels (wall evidence, doorways along lines)
    "cut_share",  # share of the border on free-space doorway cuts
    "log_area_min_m2",
    "log_area_max_m2",
    "area_ratio",  # smaller over larger area
    "elongation_min",  # area / (2 peak)^2 of the more compact piece
    "elongation_max",
    "solidity_min",  # each piece's solidity (holes filled over convex hull)
    "solidity_max",
    "solidity_union",  # the union's
    "solidity_gain",  # union's solidity minus the lower of the pieces'
)
_SADDLE, _SOLIDITY, _FURNISHED = (FEATURES.index(f) for f in ("saddle_min_peak", "solidity_union", "furniture_share"))


@dataclass(frozen=True)
class Borders:
    """Border pixel pairs of touching segments, one row per pair of 4-neighbours."""

    p: npt.NDArray[np.int64]
    q: npt.NDArray[np.int64]
    height: npt.NDArray[np.float32]
    near: npt.NDArray[np.bool_]
    closed: npt.NDArray[np.bool_]
    cut: npt.NDArray[np.bool_]
    y: npt.NDArray[np.float64]
    x: npt.NDArray[np.float64]


def borders(
    seg: npt.NDArray[np.int32],
    clearance: npt.NDArray[np.float32],
    furniture: npt.NDArray[np.bool_],
    closed: npt.NDArray[np.bool_],
    cut: npt.NDArray[np.bool_],
    reach: int,
) -> Borders:
    h, w = seg.shape
    parts: list[tuple[npt.NDArray[np.int64], ...]] = []
    sides: list[npt.NDArray[np.int64]] = []
    for dy, dx in ((0, 1), (1, 0)):
        a, b = seg[: h - dy, : w - dx], seg[dy:, dx:]
        rows, cols = np.nonzero((a != b) & (a > 0) & (b > 0))
        one = rows.astype(np.int64) * w + cols
        two = (rows.astype(np.int64) + dy) * w + cols + dx
        parts.append((a[rows, cols].astype(np.int64), b[rows, cols].astype(np.int64), rows, cols, one, two))
        sides += [one, two]
    p = np.concatenate([t[0] for t in parts])
    q = np.concatenate([t[1] for t in parts])
    one = np.concatenate([t[4] for t in parts])
    two = np.concatenate([t[5] for t in parts])
    near_both = _near(furniture, np.concatenate([one, two]), reach)
    clear = clearance.ravel()
    shut = closed.ravel()
    cuts = cut.ravel()
    y = np.concatenate([parts[0][2] + 0.0, parts[1][2] + 0.5])
    x = np.concatenate([parts[0][3] + 0.5, parts[1][3] + 0.0])
    return Borders(
        np.minimum(p, q),
        np.maximum(p, q),
        np.minimum(clear[one], clear[two]),
        near_both[: one.size] | near_both[one.size :],
        shut[one] | shut[two],
        cuts[one] | cuts[two],
        y,
        x,
    )


def _area(polygon: npt.NDArray[np.int32]) -> float:
    """Pixels covered by a closed polygon through pixel centres (half a pixel all round it)."""
    return float(cv2.contourArea(polygon) + 0.5 * cv2.arcLength(polygon, True) + 1.0)


class Pieces:
    """The segments during the joins: ids through ``lut``, pooled per-segment figures.

    A segment's outline is kept as its area with holes filled and its convex hull; two segments
    together fill the sum of their areas and their hull is the hull of both hulls, so a union's
    solidity needs no pixels.
    """

    def __init__(self, seg: npt.NDArray[np.int32], clearance: npt.NDArray[np.float32]) -> None:
        self.seg = seg
        n = int(seg.max()) + 1
        self.lut = np.arange(n, dtype=np.int64)
        self.area = np.bincount(seg.ravel(), minlength=n).astype(np.float64)
        self.clearance = clearance
        self.peak = np.zeros(n, dtype=np.float64)
        self.slices = [None, *ndimage.find_objects(seg, max_label=n - 1)]
        self.filled = np.zeros(n, dtype=np.float64)
        self.hull: dict[int, npt.NDArray[np.int32]] = {}

    def measure(self, ids: npt.NDArray[np.int64]) -> None:
        """Peak clearance, filled area and hull of these segments (of ``seg``'s own ids) not yet measured."""
        for i in ids.tolist():
            if i in self.hull:
                continue
            box = self.slices[i]
            assert box is not None
            mask = self.seg[box] == i
            self.peak[i] = float(self.clearance[box][mask].max())
            outlines, _ = cv2.findContours(
                mask.view(np.uint8), cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE, offset=(box[1].start, box[0].start)
            )
            self.filled[i] = sum(_area(c) for c in outlines)
            self.hull[i] = cv2.convexHull(np.concatenate(outlines))

    def solidity(self, a: npt.NDArray[np.int64], b: npt.NDArray[np.int64]) -> tuple[npt.NDArray[np.float64], ...]:
        """Solidity (filled area over convex hull) of each ``a``, each ``b`` and each pair together."""
        own = np.zeros(self.lut.size)
        for i in np.unique(np.concatenate([a, b])).tolist():
            own[i] = self.filled[i] / _area(self.hull[i])
        union = np.array(
            [
                (self.filled[i] + self.filled[j]) / _area(cv2.convexHull(np.concatenate([self.hull[i], self.hull[j]])))
                for i, j in zip(a.tolist(), b.tolist(), strict=True)
            ]
        )
        return own[a], own[b], union

    def join(self, a: int, b: int) -> None:
        """Segment ``b`` becomes part of ``a``."""
        self.lut[self.lut == b] = a
        self.area[a] += self.area[b]
        self.peak[a] = max(self.peak[a], self.peak[b])
        self.filled[a] += self.filled[b]
        self.hull[a] = cv2.convexHull(np.concatenate([self.hull[a], self.hull[b]]))


def pair_features(
    pieces: Pieces, border: Borders, resolution_m: float, frozen: npt.NDArray[np.bool_]
) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.float64]]:
    """Touching pairs (a < b, current ids, neither ``frozen``) and their :data:`FEATURES` (one row each)."""
    lut = pieces.lut
    p, q = lut[border.p], lut[border.q]
    apart = (p != q) & ~frozen[p] & ~frozen[q]
    n = lut.size
    a, b = np.minimum(p[apart], q[apart]), np.maximum(p[apart], q[apart])
    codes, inv = np.unique(a * n + b, return_inverse=True)
    pairs = np.stack([codes // n, codes % n], axis=1)
    m = codes.size
    if m == 0:
        return pairs, np.zeros((0, len(FEATURES)))
    pieces.measure(pairs.ravel())
    count = np.bincount(inv, minlength=m).astype(np.float64)

    def mean(v: npt.NDArray[np.generic]) -> npt.NDArray[np.float64]:
        return np.bincount(inv, weights=np.asarray(v, dtype=np.float64)[apart], minlength=m) / count

    saddle = np.zeros(m, dtype=np.float64)
    np.maximum.at(saddle, inv, border.height[apart].astype(np.float64))
    saddle = np.maximum(saddle, 1.0)
    my, mx = mean(border.y), mean(border.x)
    vyy = np.maximum(mean(border.y**2) - my**2, 0.0)
    vxx = np.maximum(mean(border.x**2) - mx**2, 0.0)
    vxy = mean(border.x * border.y) - mx * my
    major = 0.5 * (vyy + vxx) + np.sqrt(0.25 * (vyy - vxx) ** 2 + vxy**2)
    extent = np.sqrt(12.0 * major) + 1.0  # a uniform run of length L has variance L^2 / 12
    peak = np.maximum(pieces.peak, 1.0)
    pa, pb = peak[pairs[:, 0]], peak[pairs[:, 1]]
    lo_peak, hi_peak = np.minimum(pa, pb), np.maximum(pa, pb)
    area = pieces.area * resolution_m**2
    aa, ab = area[pairs[:, 0]], area[pairs[:, 1]]
    elong = pieces.area / (2.0 * peak) ** 2
    ea, eb = elong[pairs[:, 0]], elong[pairs[:, 1]]
    sa, sb, su = pieces.solidity(pairs[:, 0], pairs[:, 1])
    x = np.column_stack(
        [
            np.log(count * resolution_m),
            saddle * resolution_m,
            saddle / lo_peak,
            saddle / hi_peak,
            extent / (2.0 * lo_peak),
            extent / (2.0 * hi_peak),
            extent / (2.0 * saddle),
            mean(border.height) / saddle,
            extent / count,
            mean(border.near),
            mean(border.closed),
            mean(border.cut),
            np.log(np.minimum(aa, ab)),
            np.log(np.maximum(aa, ab)),
            np.minimum(aa, ab) / np.maximum(aa, ab),
            np.minimum(ea, eb),
            np.maximum(ea, eb),
            np.minimum(sa, sb),
            np.maximum(sa, sb),
            su,
            su - np.minimum(sa, sb),
        ]
    )
    return pairs, x


@dataclass(frozen=True)
class JoinModel:
    """Boosted decision trees over :data:`FEATURES`: the log-odds that two touching pieces are one room.

    Nodes of all trees in flat arrays; ``left``/``right`` index the same arrays, ``feature`` is -1 at a
    leaf, whose ``value`` is its (learning-rate scaled) contribution. ``roots`` lists each tree's root.
    """

    bias: float
    roots: npt.NDArray[np.int64]
    feature: npt.NDArray[np.int64]
    threshold: npt.NDArray[np.float64]
    left: npt.NDArray[np.int64]
    right: npt.NDArray[np.int64]
    value: npt.NDArray[np.float64]
    depth: int

    def log_odds(self, x: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        x = np.asarray(x, dtype=np.float32)  # as scikit-learn's trees compare them
        node = np.broadcast_to(self.roots, (x.shape[0], self.roots.size)).copy()
        rows = np.arange(x.shape[0])[:, None]
        for _ in range(self.depth):
            f = self.feature[node]
            leaf = f < 0
            go_left = x[rows, np.maximum(f, 0)] <= self.threshold[node]
            node = np.where(leaf, node, np.where(go_left, self.left[node], self.right[node]))
        out: npt.NDArray[np.float64] = self.bias + self.value[node].sum(axis=1)
        return out

    def to_json(self) -> str:
        return json.dumps(
            {
                "features": list(FEATURES),
                "bias": self.bias,
                "depth": self.depth,
                "roots": self.roots.tolist(),
                "feature": self.feature.tolist(),
                "threshold": self.threshold.tolist(),
                "left": self.left.tolist(),
                "right": self.right.tolist(),
                "value": self.value.tolist(),
            }
        )

    @classmethod
    def from_json(cls, text: str) -> JoinModel:
        data = json.loads(text)
        if tuple(data["features"]) != FEATURES:
            raise ValueError(f"join model features {data['features']} differ from {FEATURES}")
        return cls(
            float(data["bias"]),
            np.asarray(data["roots"], dtype=np.int64),
            np.asarray(data["feature"], dtype=np.int64),
            np.asarray(data["threshold"], dtype=np.float64),
            np.asarray(data["left"], dtype=np.int64),
            np.asarray(data["right"], dtype=np.int64),
            np.asarray(data["value"], dtype=np.float64),
            int(data["depth"]),
        )


@cache
def default_model() -> JoinModel:
    """The model fitted by ``bench/fit_joins.py`` and shipped with the package."""
    return JoinModel.from_json(MODEL_PATH.read_text())


def learned_joins(
    segments: npt.NDArray[np.int32],
    furniture: npt.NDArray[np.bool_],
    closed: npt.NDArray[np.bool_],
    cut: npt.NDArray[np.bool_],
    *,
    resolution_m: float,
    model: JoinModel,
    fixed: npt.NDArray[np.bool_] | None = None,
    min_log_odds: float = 0.0,
    min_saddle_ratio: float = 0.0,
    min_solidity: float = 0.0,
    furnished_only: bool = False,
    furniture_reach_m: float = 1.0,
) -> npt.NDArray[np.int32]:
    """Join touching segments that ``model`` takes for pieces of one room.

    Every round scores each touching pair from its border and its pieces (:func:`pair_features`)
    and joins the pairs above ``min_log_odds``, best first, one join per segment; the joined
    pieces' features are computed anew in the next round, until no pair is left above it. A pair
    is a candidate at all only when its saddle is at least ``min_saddle_ratio`` of the lower peak,
    its union's solidity at least ``min_solidity`` and, with ``furnished_only``, furniture lies
    within ``furniture_reach_m`` of its border (the gates of
    :func:`~services.grid_decomposition.basins.join_room_pieces`, the model then deciding among them).

    Parameters
    ----------
    segments : (H, W) int32
        Segment ids 1..N per pixel, 0 = none.
    furniture : (H, W) bool
        Obstacles standing on the floor of the rooms (floor for the clearance).
    closed, cut : (H, W) bool
        Closed line pixels (wall evidence, doorways along lines); free-space doorway cuts.
    fixed : (N + 1,) bool, optional
        Per segment id: never joined (warehouse floors, road networks).

    Returns
    -------
    (H, W) int32
        Segment ids 1..M (consecutive), 0 where ``segments`` is 0.
    """
    seg = np.asarray(segments, dtype=np.int32)
    n = int(seg.max()) + 1
    if n <= 2:
        return renumber(seg)
    floor = ((seg > 0) | furniture).astype(np.uint8)
    clearance = np.asarray(cv2.distanceTransform(floor, cv2.DIST_L2, 5), dtype=np.float32)
    border = borders(seg, clearance, furniture, closed, cut, max(1, round(furniture_reach_m / resolution_m)))
    pieces = Pieces(seg, clearance)
    frozen = np.zeros(n, dtype=bool) if fixed is None else np.asarray(fixed[:n], dtype=bool).copy()
    frozen[0] = True
    while True:
        pairs, x = pair_features(pieces, border, resolution_m, frozen)
        score = model.log_odds(x)
        gate = (x[:, _SADDLE] >= min_saddle_ratio) & (x[:, _SOLIDITY] >= min_solidity)
        if furnished_only:
            gate &= x[:, _FURNISHED] > 0
        score[~gate] = -np.inf
        order = np.argsort(-score, kind="stable")
        used = np.zeros(n, dtype=bool)
        for k in order[score[order] > min_log_odds]:
            a, b = (int(v) for v in pairs[k])
            if used[a] or used[b]:
                continue
            used[a] = used[b] = True
            pieces.join(a, b)
        if not used.any():
            return renumber(pieces.lut[seg].astype(np.int32))
