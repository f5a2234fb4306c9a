"""The kernel pairs keep detailed balance: checked on a tiny world by enumerating every draw."""

from __future__ import annotations

import math
from collections import defaultdict

import numpy as np
import numpy.typing as npt
import pytest

from services.floor_plan.chain import Chain
from services.floor_plan.context import ContextPrior, ContextSettings
from services.floor_plan.detectors import Candidate, Evidence, WallLines
from services.floor_plan.kernels import (
    Kernel,
    KernelSettings,
    Move,
    Proposer,
    RandomChooser,
    apply_move,
    interchange,
)
from services.floor_plan.likelihood import Canvas, classify_map, log_sensor_table
from services.floor_plan.world import Rect, World

T = 1  # wall cells


class _Path:
    """A chooser that follows a fixed prefix of choices, then takes the first branch, recording each fan-out."""

    def __init__(self, prefix: list[int]) -> None:
        self.prefix = prefix
        self.taken: list[int] = []
        self.fanout: list[npt.NDArray[np.float64]] = []
        self.probability = 1.0

    def pick(self, weights: npt.NDArray[np.float64]) -> int:
        p = np.asarray(weights, np.float64) / float(np.sum(weights))
        i = len(self.taken)
        k = self.prefix[i] if i < len(self.prefix) else int(np.flatnonzero(p > 0)[0])
        self.taken.append(k)
        self.fanout.append(p)
        self.probability *= float(p[k])
        return k


def _draws(proposer: Proposer, kernel: Kernel, world: World) -> list[tuple[float, Move | None]]:
    """Every way ``kernel`` can draw from ``world``, with its probability."""
    out: list[tuple[float, Move | None]] = []
    stack: list[list[int]] = [[]]
    while stack:
        prefix = stack.pop()
        path = _Path(prefix)
        move = proposer.draw(kernel, world, path)
        out.append((path.probability, move))
        for j in range(len(prefix), len(path.taken)):
            for k in np.flatnonzero(path.fanout[j] > 0):
                if k > path.taken[j]:
                    stack.append([*path.taken[:j], int(k)])
    return out


def _tiny() -> tuple[npt.NDArray[np.uint8], Proposer, ContextPrior]:
    occ = np.zeros((6, 9), np.int8)
    occ[0, :] = occ[5, :] = 100
    occ[:, 0] = occ[:, 4] = occ[:, 8] = 100
    occ[2:4, 4] = 0
    classes = classify_map(occ)
    ks = KernelSettings(wall_cells=T, min_inner_cells=1, shift_sigma_cells=1.0, max_shift_cells=1, min_door_cells=2)
    lines = WallLines(np.array([[2, 0, 8]]), np.array([[4, 0, 5]]))  # one split line each way
    cands = [Candidate(Rect(0, 5, 0, 4), 0.9), Candidate(Rect(0, 5, 4, 8), 0.8), Candidate(Rect(0, 5, 0, 8), 0.7)]
    proposer = Proposer(Evidence(classes), lines, ks, cands)
    prior = ContextPrior(resolution_m=1.0, wall_cells=T,
                         settings=ContextSettings(hall_area_m2=30.0, corridor_ratio=2.0, same_length_sigma_m=2.0))
    return classes, proposer, prior


def _chain(world: World, classes: npt.NDArray[np.uint8], proposer: Proposer, prior: ContextPrior) -> Chain:
    canvas = Canvas(classes, log_sensor_table(), wall_cells=T, log_overlap=math.log(0.3))
    return Chain(world.copy(), canvas, proposer, prior)


def _transitions(world: World, classes: npt.NDArray[np.uint8], proposer: Proposer, prior: ContextPrior,
                 used: set[Kernel]) -> tuple[float, dict[object, float], dict[object, World]]:
    """log posterior of ``world`` and the exact probability of moving to each other world (all draws summed)."""
    phi = {k: 1.0 / len(Kernel) for k in Kernel}
    chain = _chain(world, classes, proposer, prior)
    out: dict[object, float] = defaultdict(float)
    reached: dict[object, World] = {}
    for kernel in Kernel:
        for p, move in _draws(proposer, kernel, world):
            ev = chain.evaluate(move, phi) if move is not None else None
            if ev is None:
                continue
            used.add(kernel)
            key = ev.after.key()
            out[key] += phi[kernel] * p * min(1.0, math.exp(ev.log_alpha))
            reached[key] = ev.after
    return chain.log_posterior, out, reached


def test_every_kernel_pair_keeps_detailed_balance_on_a_tiny_world() -> None:
    """pi(W) P(W -> W') = pi(W') P(W' -> W) for every move out of the first worlds a breadth-first walk meets."""
    classes, proposer, prior = _tiny()
    used: set[Kernel] = set()
    cache: dict[object, tuple[float, dict[object, float], dict[object, World]]] = {}

    def explore(world: World) -> tuple[float, dict[object, float], dict[object, World]]:
        if world.key() not in cache:
            cache[world.key()] = _transitions(world, classes, proposer, prior, used)
        return cache[world.key()]

    queue, checked = [World()], 0
    seen: set[object] = {World().key()}
    while queue and checked < 40:
        world = queue.pop(0)
        checked += 1
        log_pi, out, reached = explore(world)
        for key, p_ab in out.items():
            if key == world.key():
                continue
            log_pi_b, back, _ = explore(reached[key])
            p_ba = back.get(world.key(), 0.0)
            assert p_ba > 0.0, f"a move has no way back: {world.key()} -> {key}"
            assert log_pi + math.log(p_ab) == pytest.approx(log_pi_b + math.log(p_ba), abs=1e-9)
            if key not in seen:
                seen.add(key)
                queue.append(reached[key])
    assert used == set(Kernel), f"kernels never proposing a legal move: {set(Kernel) - used}"
    assert len(seen) > 40


def test_incremental_scores_match_full_rescores_along_a_random_walk() -> None:
    """Every legal move is taken (no acceptance test) so the walk visits odd worlds; after each, the
    incrementally kept likelihood and prior equal a rescore from scratch."""
    rng = np.random.default_rng(3)
    occ = np.where(rng.random((30, 40)) < 0.8, 0, 100).astype(np.int8)
    occ[rng.random((30, 40)) < 0.1] = -1
    classes = classify_map(occ)
    ks = KernelSettings(wall_cells=2, min_inner_cells=2, shift_sigma_cells=2.0, max_shift_cells=3, min_door_cells=1)
    lines = WallLines(np.array([[r, 0, 39] for r in (6, 12, 18, 24)]), np.array([[c, 0, 29] for c in (8, 16, 24, 32)]))
    cands = []
    for _ in range(40):
        r0, c0 = int(rng.integers(0, 20)), int(rng.integers(0, 30))
        r1, c1 = min(r0 + int(rng.integers(6, 14)), 29), min(c0 + int(rng.integers(6, 14)), 39)
        cands.append(Candidate(Rect(r0, r1, c0, c1), float(rng.random()) + 0.1))
    proposer = Proposer(Evidence(classes), lines, ks, cands)
    context = ContextSettings(hall_area_m2=20.0, corridor_ratio=2.0)
    prior = ContextPrior(resolution_m=0.5, wall_cells=2, settings=context)
    canvas = Canvas(classes, log_sensor_table(), wall_cells=2, log_overlap=math.log(0.3))
    chain = Chain(World(), canvas, proposer, prior)
    chooser = RandomChooser(rng)
    phi = {k: 1.0 / len(Kernel) for k in Kernel}
    taken: set[Kernel] = set()
    for _ in range(1500):
        kernel = list(Kernel)[int(rng.integers(len(Kernel)))]
        move = proposer.draw(kernel, chain.world, chooser)
        ev = chain.evaluate(move, phi) if move is not None else None
        if ev is None:
            continue
        chain.accept(ev)
        taken.add(kernel)
        assert chain.canvas.score == pytest.approx(chain.canvas.rescore(), abs=1e-6), kernel
        assert chain.log_prior == pytest.approx(prior.total(chain.world), abs=1e-9), kernel
    assert taken >= {Kernel.ADD, Kernel.REMOVE, Kernel.SHRINK, Kernel.DILATE, Kernel.SPLIT}


def test_interchange_cuts_an_l_shape_the_other_way_and_back() -> None:
    top, low = Rect(0, 5, 0, 9), Rect(5, 12, 0, 4)  # low hangs under the left half of top
    swapped = interchange(top, low, 1)
    assert swapped is not None
    assert set(swapped) == {Rect(0, 12, 0, 4), Rect(0, 5, 4, 9)}
    back = interchange(*swapped, 1)
    assert back is not None and set(back) == {top, low}


def test_split_then_merge_restores_the_unit() -> None:
    _, proposer, _ = _tiny()
    world = World({1: Rect(0, 5, 0, 8)}, set(), 2)
    moves = [m for _, m in _draws(proposer, Kernel.SPLIT, world) if m is not None]
    assert moves
    for move in moves:
        after, _ = apply_move(world, move)
        a, b = after.units.values()
        merged = proposer.merged(a, b)
        assert merged is not None and merged[0] == Rect(0, 5, 0, 8)
