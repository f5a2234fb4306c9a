"""Load scenes: bin occupancy, support relations, hidden objects, false estimates and speed on synthetic bays.

Prints ``name value unit`` lines. Seeded synthetic bays (services.load_scenes.synthetic): single and double
deep, 2-5 levels, pallets with blocks or carton stacks, overhanging cartons, hidden second-deep pallets,
missed detections and ghosts, one aisle depth view per bay. The settings were tuned on seeds 0-2 (noise
sigma 2 cm); seeds 10-12 are held out with more noise (3 cm), more misses and more ghosts.

Figures per set:
- occupancy accuracy over the bins the view saw (rays through the front opening), and how many of those
  were answered unknown;
- support-relation accuracy over all pairs of true objects (beam pairs and floor included) and over the
  pairs related in the truth or the answer (supports in either direction or unstable contact);
- hidden objects found (true objects nobody detected with a detected object resting on them, matched to an
  added ``hidden_below`` node by overlap) and false estimates found (ghosts flagged ``false_estimate``),
  with false alarms: real detections flagged false, and added hidden nodes that match no missed object;
- process time per bay scene graph (one thread), median and 95th percentile, for bays with <= 12 detections
  and for all.

Run: ``PYTHONPATH=. .venv/bin/python bench/bench_load_scenes.py [--bays 60] [--settings JSON] [--tune-only]``
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from threadpoolctl import threadpool_limits

from services.load_scenes import InferenceSettings, bin_evidence, bin_occupancy, infer_bay_scene
from services.load_scenes import synthetic as syn
from services.load_scenes.boxes import SUPPORT, Boxes, boxes_from_nodes
from services.load_scenes.model import Flag, ObjectKind, Occupancy, Relation, SceneGraph

HELD_OUT_NOISE = syn.NoiseModel(sigma_m=(0.03, 0.03, 0.02), miss_rate=0.05, ghosts_per_bay=0.45, range_sigma_m=0.015)


def _covered(node: Boxes, k: int, truth: Boxes) -> np.ndarray:
    """Fraction of each true box's volume inside node k, and whether their tops agree within 10 cm."""
    lo = np.maximum(node.centre[k] - node.half[k], truth.centre - truth.half)
    hi = np.minimum(node.centre[k] + node.half[k], truth.centre + truth.half)
    inter = np.prod(np.clip(hi - lo, 0.0, None), axis=1)
    frac = inter / np.prod(2 * truth.half, axis=1)
    return np.where(np.abs(truth.top - node.top[k]) < 0.1, frac, 0.0)


def _node_truth(sb: syn.SyntheticBay, graph: SceneGraph) -> tuple[dict[str, int], list[str]]:
    """Graph node id -> truth index; unmatched hidden nodes.

    Supports by level, detections through the synthetic ids, an added hidden node to the missed true box
    right under what it carries: the one whose top it shares (within 10 cm) and whose volume it mostly covers
    (a hidden node may span two stacked missed cartons; it stands for the upper one).
    """
    index = {t: k for k, t in enumerate(sb.truth_ids)}
    out: dict[str, int] = {}
    sup_nodes = [nd for nd in graph.nodes if nd.kind == ObjectKind.BEAM]
    for level, nd in enumerate(sup_nodes):
        out[nd.id] = level
    for nd in graph.nodes:
        t = sb.estimate_truth.get(nd.id)
        if t is not None and Flag.FALSE_ESTIMATE not in nd.flags:
            out[nd.id] = index[t]
    hidden = [nd for nd in graph.nodes if Flag.HIDDEN_BELOW in nd.flags]
    unmatched = []
    missed = np.array([index[t] for t in sorted(sb.missed)], int)
    if hidden:
        boxes = boxes_from_nodes(sb.bay, hidden)
        truth = Boxes(*(getattr(sb.truth, f)[missed] for f in
                        ("centre", "half", "size", "yaw", "sigma", "kind", "level", "score")))
        for k, nd in enumerate(hidden):
            cover = _covered(boxes, k, truth) if missed.size else np.zeros(1)
            if cover.max() >= 0.5:
                out[nd.id] = int(missed[int(np.argmax(cover))])
            else:
                unmatched.append(nd.id)
    return out, unmatched


def _pairs(sb: syn.SyntheticBay, graph: SceneGraph, match: dict[str, int], *,
           observable_only: bool) -> tuple[int, int, int, int]:
    """(right, all, right related, related) over unordered pairs of true boxes.

    ``observable_only`` leaves out pairs with a true box no view can reveal: missed by the detector with no
    detection resting on it (e.g. a second-deep stack wholly behind a front one)."""
    sup_t, uns_t = sb.truth_relations()
    n = len(sb.truth_ids)
    pred = np.zeros((n, n), np.int8)  # 1: row supports column, 2: unstable contact
    for e in graph.edges:
        a, b = match.get(e.source), match.get(e.target)
        if a is None or b is None:
            continue
        if e.relation == Relation.SUPPORTS:
            pred[a, b] = 1
        else:
            pred[a, b] = pred[b, a] = 2
    truth = np.where(sup_t, 1, np.where(uns_t, 2, 0)).astype(np.int8)
    iu = np.triu_indices(n, 1)
    t_pair = np.stack([truth[iu], truth.T[iu]], axis=1)
    p_pair = np.stack([pred[iu], pred.T[iu]], axis=1)
    same = (t_pair == p_pair).all(axis=1)
    index = {t: k for k, t in enumerate(sb.truth_ids)}
    unknowable = np.zeros(n, bool)
    unknowable[[index[t] for t in sb.missed - sb.hidden]] = True
    keep = ~((sb.truth.kind[iu[0]] == SUPPORT) & (sb.truth.kind[iu[1]] == SUPPORT))
    if observable_only:
        keep &= ~unknowable[iu[0]] & ~unknowable[iu[1]]
    same, t_pair, p_pair = same[keep], t_pair[keep], p_pair[keep]
    related = (t_pair != 0).any(axis=1) | (p_pair != 0).any(axis=1)
    return int(same.sum()), int(same.size), int(same[related].sum()), int(related.sum())


def run_set(name: str, seeds: list[int], bays: int, noise: syn.NoiseModel | None,
            settings: InferenceSettings) -> None:
    c = dict.fromkeys(["bins", "bins_right", "bins_unknown", "pairs", "pairs_right", "rel", "rel_right",
                       "hidden", "hidden_found", "ghosts", "ghosts_found", "real", "real_flagged", "added",
                       "added_unmatched", "skipped", "obs_pairs", "obs_pairs_right", "obs_rel", "obs_rel_right",
                       "unknowable", "objects"], 0)
    times_small: list[float] = []
    times_all: list[float] = []
    occ_times: list[float] = []
    for seed in seeds:
        for k in range(bays):
            sb = syn.synthetic_bay(seed, k, noise)
            t0 = time.process_time()
            res = infer_bay_scene(sb.bay, sb.estimates, sb.evidence, settings)
            dt = time.process_time() - t0
            t1 = time.process_time()
            bins = bin_occupancy(sb.bay, res.graph, bin_evidence(sb.bay, res.graph, sb.evidence))
            occ_times.append(time.process_time() - t1)
            times_all.append(dt)
            if len(sb.estimates) <= 12:
                times_small.append(dt)
            g = res.graph
            c["skipped"] += len(res.skipped)
            truth_occ = sb.occupied()
            for level, b in enumerate(bins):
                if b.views == 0:
                    continue
                c["bins"] += 1
                c["bins_unknown"] += b.state == Occupancy.UNKNOWN
                want = Occupancy.OCCUPIED if truth_occ[level] else Occupancy.EMPTY
                c["bins_right"] += b.state == want
            match, unmatched = _node_truth(sb, g)
            for tag, only in (("", False), ("obs_", True)):
                right, total, rel_right, rel = _pairs(sb, g, match, observable_only=only)
                c[tag + "pairs_right"] += right
                c[tag + "pairs"] += total
                c[tag + "rel_right"] += rel_right
                c[tag + "rel"] += rel
            c["unknowable"] += len(sb.missed - sb.hidden)
            c["objects"] += len(sb.truth_ids) - len(sb.bay.levels_z_m)
            index = {t: i for i, t in enumerate(sb.truth_ids)}
            found = set(match.values())
            c["hidden"] += len(sb.hidden)
            c["hidden_found"] += sum(index[t] in found for t in sb.hidden)
            flagged = {nd.id for nd in g.nodes if Flag.FALSE_ESTIMATE in nd.flags}
            c["ghosts"] += len(sb.ghosts)
            c["ghosts_found"] += len(sb.ghosts & flagged)
            real = set(sb.estimate_truth) - sb.ghosts
            c["real"] += len(real)
            c["real_flagged"] += len(real & flagged)
            c["added"] += sum(Flag.HIDDEN_BELOW in nd.flags for nd in g.nodes)
            c["added_unmatched"] += len(unmatched)
    n = len(seeds) * bays
    print(f"{name}_bays {n} bays")
    print(f"{name}_bins_seen {c['bins']} bins")
    print(f"{name}_occupancy_accuracy {100 * c['bins_right'] / max(c['bins'], 1):.2f} %")
    print(f"{name}_occupancy_unknown {100 * c['bins_unknown'] / max(c['bins'], 1):.2f} %")
    print(f"{name}_support_pairs_accuracy {100 * c['pairs_right'] / max(c['pairs'], 1):.2f} %")
    print(f"{name}_support_related_pairs_accuracy {100 * c['rel_right'] / max(c['rel'], 1):.2f} %")
    print(f"{name}_support_observable_pairs_accuracy {100 * c['obs_pairs_right'] / max(c['obs_pairs'], 1):.2f} %")
    print(f"{name}_support_observable_related_pairs_accuracy "
          f"{100 * c['obs_rel_right'] / max(c['obs_rel'], 1):.2f} %")
    print(f"{name}_unknowable_objects {100 * c['unknowable'] / max(c['objects'], 1):.1f} % of {c['objects']}")
    print(f"{name}_hidden_found {100 * c['hidden_found'] / max(c['hidden'], 1):.1f} % of {c['hidden']}")
    print(f"{name}_ghosts_found {100 * c['ghosts_found'] / max(c['ghosts'], 1):.1f} % of {c['ghosts']}")
    print(f"{name}_real_flagged_false {100 * c['real_flagged'] / max(c['real'], 1):.2f} % of {c['real']}")
    print(f"{name}_hidden_unmatched {100 * c['added_unmatched'] / max(c['added'], 1):.2f} % of {c['added']}")
    for label, ts in (("le12", times_small), ("all", times_all)):
        if ts:
            print(f"{name}_ms_per_bay_{label}_median {1000 * float(np.median(ts)):.1f} ms (process time, n={len(ts)})")
            print(f"{name}_ms_per_bay_{label}_p95 {1000 * float(np.percentile(ts, 95)):.1f} ms")
    print(f"{name}_ms_per_bay_occupancy_median {1000 * float(np.median(occ_times)):.2f} ms")
    print(f"{name}_skipped_estimates {c['skipped']} estimates")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    parser.add_argument("--bays", type=int, default=60, help="bays per seed")
    parser.add_argument("--settings", default="{}", help="InferenceSettings as JSON (defaults: the tuned ones)")
    parser.add_argument("--tune-only", action="store_true", help="skip the held-out seeds")
    args = parser.parse_args()
    settings = InferenceSettings.model_validate_json(args.settings)
    with threadpool_limits(1):
        wall = time.perf_counter()
        run_set("tune", [0, 1, 2], args.bays, None, settings)
        if not args.tune_only:
            run_set("heldout", [10, 11, 12], args.bays, HELD_OUT_NOISE, settings)
        print(f"bench_wall {time.perf_counter() - wall:.1f} s")


if __name__ == "__main__":
    main()
