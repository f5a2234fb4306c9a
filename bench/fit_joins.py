"""Fit the room-join classifier (``services/grid_decomposition/data/join_model.json``) on the ipa maps.

Every ipa map (plain and each variant) is decomposed with the joins off; at the room stage's join
step every pair of touching pieces gets its features (:func:`~services.grid_decomposition.joins.pair_features`)
and a label from the ground truth: one room when both pieces lie mostly in the same ground-truth room.
The pieces of each room are then joined as the ground truth says, and the pairs left (whole rooms side
by side, the pairs a good join step still sees in its last round) are added as well. Gradient-boosted
trees (scikit-learn) are fitted on all of them and written as JSON.

``--maps`` fits on some maps only (leave-maps-out figures), ``--pairs`` caches the captured pairs.
Run: ``PYTHONPATH=. .venv/bin/python bench/fit_joins.py [--maps NAME ...] [--out PATH]``.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from sklearn.ensemble import GradientBoostingClassifier
from threadpoolctl import threadpool_limits

sys.path.insert(0, str(Path(__file__).resolve().parent))
import eval_ipa

from services.grid_decomposition import decompose, ground_truth_rooms, pipeline, rooms
from services.grid_decomposition.basins import join_room_pieces
from services.grid_decomposition.joins import MODEL_PATH, JoinModel, Pieces, borders, pair_features
from services.grid_decomposition.mapfile import read_map_file

RES = 0.05
captured: dict[str, Any] = {}
original = rooms.segment_rooms


def wrapper(segments, clutter, floor, closed, **kw):  # type: ignore[no-untyped-def]
    pieces, cut = original(segments, clutter, floor, closed, **{**kw, "join_saddle_ratio": 0.0, "join_model": None})
    standing = clutter | rooms.islands(pieces == 0, max_extent_px=3.0 / RES)
    fixed = rooms._share(pieces, floor) > 0.5
    captured.update(seg=pieces, standing=standing, closed=closed, cut=cut, fixed=fixed)
    return join_room_pieces(pieces, standing, resolution_m=RES, fixed=fixed), cut


pipeline.segment_rooms = wrapper


def rows_for(gt_image: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Features, labels, round, purity for the captured map; ``gt_image`` in grid order, 0 = no room."""
    seg, standing, closed, cut, fixed = (captured[k] for k in ("seg", "standing", "closed", "cut", "fixed"))
    floor = ((seg > 0) | standing).astype(np.uint8)
    clearance = np.asarray(cv2.distanceTransform(floor, cv2.DIST_L2, 5), dtype=np.float32)
    border = borders(seg, clearance, standing, closed, cut, reach=round(1.0 / RES))
    pieces = Pieces(seg, clearance)
    n = int(seg.max()) + 1
    r = int(gt_image.max()) + 1
    on = (seg > 0) & (gt_image > 0)
    counts = np.bincount(seg[on].astype(np.int64) * r + gt_image[on], minlength=n * r).reshape(n, r)
    major = counts.argmax(axis=1)
    size = np.bincount(seg.ravel(), minlength=n)
    purity = counts.max(axis=1) / np.maximum(size, 1)
    out: list[tuple[np.ndarray, ...]] = []
    frozen = fixed.copy()
    frozen[0] = True
    for rnd in range(2):
        pairs, x = pair_features(pieces, border, RES, frozen)
        same = (major[pairs[:, 0]] == major[pairs[:, 1]]) & (major[pairs[:, 0]] > 0)
        pur = np.minimum(purity[pairs[:, 0]], purity[pairs[:, 1]])
        out.append((x, same, np.full(len(pairs), rnd), pur))
        if rnd == 0:  # oracle joins, then the pairs left
            for a, b in pairs[same]:
                la, lb = pieces.lut[a], pieces.lut[b]
                if la != lb:
                    pieces.join(int(min(la, lb)), int(max(la, lb)))
            counts2 = np.zeros((n, r))
            np.add.at(counts2, pieces.lut, counts)
            size2 = np.bincount(pieces.lut, weights=size, minlength=n)
            major = counts2.argmax(axis=1)
            purity = counts2.max(axis=1) / np.maximum(size2, 1)
    return tuple(np.concatenate(c) for c in zip(*out, strict=True))  # type: ignore[return-value]


def capture(variants: list[str]) -> dict[str, np.ndarray]:
    """Features, labels and map names of the pairs of every ipa map (plain = '') of ``variants``."""
    data: dict[str, list[Any]] = {k: [] for k in ("x", "y", "round", "purity", "map", "set")}
    names = sorted(p.name[: -len("_gt_segmentation.png")] for p in eval_ipa.IPA.glob("*_gt_segmentation.png"))
    for variant in variants:
        for name in names:
            path = eval_ipa.IPA / f"{name}{variant}.png"
            if not path.exists():
                continue
            occ, _, _ = read_map_file(path, resolution_m=RES)
            truth = ground_truth_rooms(eval_ipa._grey(eval_ipa.IPA / f"{name}_gt_segmentation.png"))
            if occ.shape != truth.shape:
                continue
            decompose(occ, resolution_m=RES, learned_joins=False)
            x, y, rnd, pur = rows_for(np.ascontiguousarray(truth[::-1]))
            for k, v in zip(("x", "y", "round", "purity"), (x, y, rnd, pur), strict=True):
                data[k].append(v)
            data["map"].append(np.full(len(y), name))
            data["set"].append(np.full(len(y), "ipa" + variant))
            print(f"{name}{variant}: {len(y)} pairs, {int(y.sum())} of one room", flush=True)
    return {k: np.concatenate(v) for k, v in data.items()}


def fit(x: np.ndarray, y: np.ndarray) -> JoinModel:
    """Gradient-boosted trees on the pairs, as a :class:`JoinModel`."""
    gb = GradientBoostingClassifier(n_estimators=60, max_depth=3, learning_rate=0.1, subsample=0.8, random_state=0)
    gb.fit(x, y)
    trees = [est[0].tree_ for est in gb.estimators_]
    offsets = np.cumsum([0] + [t.node_count for t in trees])
    pairs = list(zip(trees, offsets, strict=False))
    left = np.concatenate([np.where(t.children_left < 0, -1, t.children_left + o) for t, o in pairs])
    right = np.concatenate([np.where(t.children_right < 0, -1, t.children_right + o) for t, o in pairs])
    feature = np.concatenate([np.where(t.children_left < 0, -1, t.feature) for t in trees])
    model = JoinModel(
        bias=float(gb._raw_predict_init(x[:1])[0, 0]),
        roots=offsets[:-1].astype(np.int64),
        feature=feature.astype(np.int64),
        threshold=np.concatenate([t.threshold for t in trees]),
        left=left.astype(np.int64),
        right=right.astype(np.int64),
        value=np.concatenate([gb.learning_rate * t.value[:, 0, 0] for t in trees]),
        depth=gb.max_depth,
    )
    np.testing.assert_allclose(model.log_odds(x), gb.decision_function(x), atol=1e-9)
    return model


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--variants", nargs="*", default=list(eval_ipa.VARIANTS), help="ipa suffixes, '' = plain")
    ap.add_argument("--maps", nargs="*", default=None, help="fit on these ipa map names only")
    ap.add_argument("--pairs", type=Path, default=None, help="cache of the captured pairs (.npz)")
    ap.add_argument("--out", type=Path, default=MODEL_PATH)
    args = ap.parse_args()
    with threadpool_limits(1):
        if args.pairs is not None and args.pairs.exists():
            data = dict(np.load(args.pairs))
        else:
            data = capture(args.variants)
            if args.pairs is not None:
                np.savez(args.pairs, **data)
    use = np.isin(data["set"], ["ipa" + v for v in args.variants])
    if args.maps:
        use &= np.isin(data["map"], args.maps)
    model = fit(data["x"][use], data["y"][use])
    args.out.write_text(model.to_json() + "\n")
    print(f"{int(use.sum())} pairs ({int(data['y'][use].sum())} of one room) from "
          f"{len(np.unique(data['map'][use]))} maps: {args.out}")


if __name__ == "__main__":
    main()
