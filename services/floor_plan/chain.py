"""Data-driven Metropolis-Hastings over worlds (algorithm 1, eq. 3.9) with the schedule of table 3.2."""

from __future__ import annotations

import math
import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np
import numpy.typing as npt

from services.floor_plan.context import ContextPrior
from services.floor_plan.detectors import fsu_candidates
from services.floor_plan.kernels import (
    REVERSE,
    Kernel,
    Move,
    Proposer,
    RandomChooser,
    apply_move,
    reverse_move,
)
from services.floor_plan.likelihood import Canvas, CellOp, door_op, unit_op
from services.floor_plan.world import World, in_wall


@dataclass(frozen=True)
class Phase:
    """Kernel probabilities Phi(W'|W) up to (and including) iteration ``until`` (None: to the end)."""

    until: int | None
    probabilities: Mapping[Kernel, float]


SEED_SCHEDULE: tuple[Phase, ...] = (
    Phase(1000, {Kernel.ADD: 0.8, Kernel.REMOVE: 0.2}),
    Phase(4000, {Kernel.ADD: 0.05, Kernel.REMOVE: 0.05, Kernel.SPLIT: 0.15, Kernel.MERGE: 0.15,
                 Kernel.SHRINK: 0.15, Kernel.DILATE: 0.15, Kernel.INTERCHANGE: 0.3}),
    Phase(None, {Kernel.ADD: 0.05, Kernel.REMOVE: 0.05, Kernel.SPLIT: 0.15, Kernel.MERGE: 0.15,
                 Kernel.SHRINK: 0.15, Kernel.DILATE: 0.15, Kernel.INTERCHANGE: 0.2, Kernel.ALLOCATE: 0.05,
                 Kernel.DELETE: 0.05}),
)
"""Table 3.2."""


@dataclass(frozen=True)
class ChainSettings:
    """Length, schedule and seed of a chain. Iterations and wall time are both bounded."""

    iterations: int = 20000
    max_seconds: float = 60.0
    schedule: tuple[Phase, ...] = SEED_SCHEDULE
    fsu_from: int = 1
    fsu_every: int = 200
    seed: int = 0
    kernels: tuple[Kernel, ...] = field(default_factory=lambda: tuple(Kernel))
    restarts: int = 2
    """Independent chains of ``iterations`` each from an empty world (a cold start; a warm start runs one): the world
    of the highest log posterior is kept. Chain 0 draws from ``seed``, chain i from the stream ``(seed, i)``; 1: the
    one chain of table 3.2 (docs/floor_plan.md, branch ``fpchain``: the chain seed's spread on ipa)."""


def phase_at(schedule: tuple[Phase, ...], iteration: int) -> Phase:
    for phase in schedule:
        if phase.until is None or iteration <= phase.until:
            return phase
    return schedule[-1]


class Evaluated(NamedTuple):
    """A move scored against the current world."""

    after: World
    log_alpha: float  # log of the MH ratio (before the min with 1)
    log_likelihood_delta: float
    log_prior_delta: float
    ops: list[CellOp]


class Chain:
    """The current world, its canvas and the machinery to propose, score and accept moves."""

    def __init__(self, world: World, canvas: Canvas, proposer: Proposer, prior: ContextPrior) -> None:
        self.world = world
        self.canvas = canvas
        self.proposer = proposer
        self.prior = prior
        self.wall_cells = proposer.settings.wall_cells
        ops = [unit_op(1, r) for r in world.units.values()] + [door_op(1, d) for d in world.doors]
        canvas.commit(ops, canvas.delta(ops, (canvas.full,)) if ops else 0.0)
        self.log_prior = prior.total(world)

    @property
    def log_posterior(self) -> float:
        return self.canvas.score + self.log_prior

    def _door_holders(self, world: World, move: Move) -> set[int]:
        out: set[int] = set()
        for door in (move.door_added, move.door_removed):
            if door is not None:
                out.update(uid for uid, r in world.units.items()  # the bounds test first: most units are elsewhere
                           if r.r0 <= door.r0 and door.r1 <= r.r1 and r.c0 <= door.c0 and door.c1 <= r.c1
                           and in_wall(r, door, self.wall_cells))
        return out

    def evaluate(self, move: Move, probabilities: Mapping[Kernel, float]) -> Evaluated | None:
        """Score ``move``; None if it leads outside the worlds the model allows or cannot be reversed."""
        world = self.world
        after, new_ids = apply_move(world, move)
        if len(set(after.units.values())) < len(after.units):
            return None  # two units on the same rectangle: not a world the model allows
        near = [world.units[u] for u in move.removed] + list(move.added) + (
            [move.door_added] if move.door_added is not None else [])
        if after.doors and not after.doors_valid(self.wall_cells, near):
            return None
        back = reverse_move(move, world, new_ids)
        q_back = probabilities.get(REVERSE[move.kernel], 0.0) * self.proposer.probability(after, back)
        if q_back <= 0.0:
            return None
        q_fwd = probabilities[move.kernel] * self.proposer.probability(world, move)
        ops = ([unit_op(-1, world.units[u]) for u in move.removed] + [unit_op(1, r) for r in move.added]
               + ([door_op(-1, move.door_removed)] if move.door_removed is not None else [])
               + ([door_op(1, move.door_added)] if move.door_added is not None else []))
        dl = self.canvas.delta(ops, move.window)
        dp = (self.prior.local(after, set(new_ids) | self._door_holders(after, move))
              - self.prior.local(world, set(move.removed) | self._door_holders(world, move)))
        return Evaluated(after, dl + dp + math.log(q_back) - math.log(q_fwd), dl, dp, ops)

    def accept(self, ev: Evaluated) -> None:
        self.canvas.commit(ev.ops, ev.log_likelihood_delta)
        self.log_prior += ev.log_prior_delta
        self.world = ev.after


class ChainResult(NamedTuple):
    world: World  # the best (maximum posterior) world seen
    log_posterior: float
    iterations: int
    accepted: int
    seconds: float
    cpu_seconds: float


def run_chain(chain: Chain, classes_map: npt.NDArray[np.uint8], settings: ChainSettings, *,
              first_iteration: int = 1, positions_rc: npt.NDArray[np.int64] | None = None,
              stream: int = 0) -> ChainResult:
    """Run Metropolis-Hastings from ``chain``'s world; stop after ``settings.iterations`` or ``max_seconds``.

    ``first_iteration`` > 1 starts inside the schedule (a warm start skips the initial ADD phase).
    ``positions_rc`` ((N, 2) cells) are where robots were: seeds of the free-space detector. ``stream`` > 0 draws
    from the random stream ``(settings.seed, stream)`` (an independent chain).
    """
    rng = np.random.default_rng([settings.seed, stream] if stream else settings.seed)
    chooser = RandomChooser(rng)
    allowed = set(settings.kernels)
    phases: dict[int, tuple[dict[Kernel, float], list[Kernel], npt.NDArray[np.float64]]] = {}
    for phase in settings.schedule:  # each phase's allowed kernels and their weights, built once
        probs = {k: p for k, p in phase.probabilities.items() if k in allowed and p > 0}
        phases[id(phase)] = probs, list(probs), np.array(list(probs.values()))
    start, cpu_start = time.perf_counter(), time.process_time()
    best, best_score = chain.world.copy(), chain.log_posterior
    accepted = 0
    base_candidates = list(chain.proposer.candidates)
    last = first_iteration + settings.iterations - 1
    it = first_iteration - 1
    for it in range(first_iteration, last + 1):
        if it % 256 == 0 and time.perf_counter() - start > settings.max_seconds:
            break
        if it >= settings.fsu_from and (it - settings.fsu_from) % settings.fsu_every == 0:
            extra = fsu_candidates(classes_map, chain.canvas.classes(), chain.proposer.evidence,
                                   wall_cells=chain.wall_cells,
                                   min_inner_cells=chain.proposer.settings.min_inner_cells,
                                   positions_rc=positions_rc)
            chain.proposer.set_candidates(base_candidates, extra)
        probs, kernels, weights = phases[id(phase_at(settings.schedule, it))]
        kernel = kernels[chooser.pick(weights)]
        move = chain.proposer.draw(kernel, chain.world, chooser)
        if move is None:
            continue
        ev = chain.evaluate(move, probs)
        if ev is None or math.log(1.0 - rng.random()) >= ev.log_alpha:
            continue
        chain.accept(ev)
        accepted += 1
        if chain.log_posterior > best_score:
            best, best_score = chain.world.copy(), chain.log_posterior
    return ChainResult(best, best_score, it - first_iteration + 1, accepted, time.perf_counter() - start,
                       time.process_time() - cpu_start)
