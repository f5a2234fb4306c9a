"""Running Aisle: stage workers and the API in one process, or one stage per process."""

from __future__ import annotations

import logging
import os
import signal
import sys
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from types import FrameType
from typing import NoReturn

from shared.bus import Bus
from shared.settings import STAGES, Settings
from shared.store import MapStore, StoreError
from shared.worker import StageFactory, run_stage

log = logging.getLogger(__name__)

STREAMS_CUT_AFTER_S = 3
"""On shutdown, how long the API waits for open requests (event streams never end by themselves), seconds."""


def stage_factories() -> dict[str, StageFactory]:
    """Every stage Aisle can run, by name (imported lazily: stages pull in heavy libraries).

    Each factory builds its stage from the stage's own settings section (``context.settings.<section>``).
    """
    from services.floor_plan.worker import floor_plan_stage
    from services.grid_decomposition.worker import decomposition_stage
    from services.load_scenes.worker import load_scenes_stage
    from services.object_labelling.worker import labelling_stage
    from services.occupancy_mapping.worker import occupancy_stage
    from services.pillar_mapping.worker import pillar_stage
    from services.semantic_fusion.worker import fusion_stage

    factories: dict[str, StageFactory] = {
        "occupancy_mapping": occupancy_stage,
        "grid_decomposition": decomposition_stage,
        "pillar_mapping": pillar_stage,
        "object_labelling": labelling_stage,
        "semantic_fusion": fusion_stage,
        "floor_plan": floor_plan_stage,
        "load_scenes": load_scenes_stage,
    }
    assert set(factories) == set(STAGES)
    return factories


@contextmanager
def stop_on_signals(stop: threading.Event) -> Iterator[None]:
    """Set ``stop`` on SIGINT or SIGTERM for the duration of the block (main thread only)."""

    def handler(signum: int, _frame: FrameType | None) -> None:
        log.info("received %s, shutting down", signal.Signals(signum).name)
        stop.set()

    previous = {sig: signal.signal(sig, handler) for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield
    finally:
        for sig, old in previous.items():
            signal.signal(sig, old)


def open_store(settings: Settings) -> MapStore:
    """The map store of ``settings``, its schema brought up to date."""
    store = MapStore(settings.database_url, layer_history=settings.layer_history)
    store.upgrade()
    return store


def key_box(secret: str) -> str:
    """The first admin key framed in a box of ``#``, with how to use it, so that nobody scrolling a log misses it."""
    lines = ["FIRST ADMIN API KEY (shown only this once; keep it safe):", "", f"    {secret}", "",
             "Send it as the header `X-API-Key: <key>`; make more keys with",
             "`aisle keys create --role read|write|admin --name NAME`."]
    width = max(len(line) for line in lines)
    rule = "#" * (width + 6)
    return "\n".join(["", rule, *(f"#  {line:<{width}}  #" for line in lines), rule])


def announce_first_admin_key(store: MapStore) -> str | None:
    """Create the first admin API key when the store has no active one, and log it in a :func:`key_box` (as a
    warning, so every log level shows it); its secret, or None when an admin key exists already."""
    from shared.store.keys import ensure_admin_key

    secret = ensure_admin_key(store)
    if secret is not None:
        log.warning("%s", key_box(secret))
    return secret


def compact_periodically(store: MapStore, settings: Settings, stop: threading.Event) -> None:
    """Thin every map's revisions by ``settings.retention`` every ``compact_period_s`` (0: never) until ``stop`` (no
    VACUUM: the database reuses the space freed)."""
    period = settings.retention.compact_period_s
    while period > 0 and not stop.wait(period):
        try:
            for map_info in store.maps():
                log.info("%s", store.compact(map_info.id, settings.retention.policy()).describe())
        except StoreError as err:
            log.warning("compaction failed, will try again in %.0f s: %s", period, err)


def run(
    settings: Settings,
    *,
    stages: Sequence[str],
    api: bool,
    stop: threading.Event,
    extra: Sequence[Callable[[Bus, threading.Event], None]] = (),
    compact: bool = False,
    expected_workers: Sequence[str] | None = None,
) -> list[str]:
    """Run ``stages`` (and the API if ``api``) until ``stop`` is set; then shut down cleanly.

    After ``stop`` every thread gets ``settings.shutdown_grace_s`` to finish (a stage stores what it has, the API
    cuts open event streams after :data:`STREAMS_CUT_AFTER_S`); the names of those still running then are
    returned, after the store has let the writes under way finish and refuses later ones
    (:meth:`MapStore.stop_writes`): a caller about to exit leaves them with :func:`exit_now`.

    ``extra`` callables run in their own threads with the bus (e.g. a bag replay); ``compact`` also thins old
    revisions now and then (:func:`compact_periodically`). The API's health check is degraded while a worker of
    ``expected_workers`` is not alive (default: ``stages``; ``aisle serve``, which runs none itself, expects the
    deployment's ``settings.stages``, each in its own process).
    """
    factories = stage_factories()
    unknown = set(stages) - set(factories)
    if unknown:
        raise ValueError(f"unknown stage(s) {sorted(unknown)}; known: {sorted(factories)}")
    store = open_store(settings)
    with Bus.open(settings.zenoh, domain_id=settings.ros_domain_id) as bus:
        threads = [
            threading.Thread(target=run_stage, name=name, args=(name, factories[name]),
                             kwargs={"bus": bus, "store": store, "settings": settings, "stop": stop})
            for name in stages
        ]
        threads += [threading.Thread(target=job, args=(bus, stop),
                                     name=getattr(getattr(job, "func", job), "__name__", "job"))  # a partial's own
                    for job in extra]
        if compact:
            threads.append(threading.Thread(target=compact_periodically, args=(store, settings, stop),
                                            name="compaction"))
        server = None
        if api:
            import uvicorn

            from api.app import create_app

            announce_first_admin_key(store)
            app = create_app(store=store, settings=settings, bus=bus,
                             expected_workers=stages if expected_workers is None else expected_workers,
                             require_keys_for_reads=settings.reads_need_key,
                             rate_limit_per_s=settings.api_rate_limit_per_s,
                             rate_limit_burst=settings.api_rate_limit_burst, cors_origins=settings.api_cors_origins,
                             event_poll_s=settings.api_event_poll_s, event_heartbeat_s=settings.api_event_heartbeat_s,
                             live_staleness_s=settings.api_live_staleness_s, key_recheck_s=settings.api_key_recheck_s,
                             gzip_min_bytes=settings.api_gzip_min_bytes)
            # an open event stream (a viewer in a browser tab) would hold a graceful shutdown for ever
            server = uvicorn.Server(uvicorn.Config(app, host=settings.api_host, port=settings.api_port,
                                                   log_level=settings.log_level.lower(), access_log=False,
                                                   timeout_graceful_shutdown=STREAMS_CUT_AFTER_S))
            threads.append(threading.Thread(target=server.run, name="api"))
        for thread in threads:
            thread.start()
        log.info("running %s%s", ", ".join(stages) or "no stages",
                 f" and the API on http://{settings.api_host}:{settings.api_port}" if api else "")
        try:
            while not stop.wait(0.5):
                if server is not None and not threads[-1].is_alive():
                    log.error("the API server stopped (port %d taken?); shutting down", settings.api_port)
                    stop.set()
        finally:
            stop.set()
            if server is not None:
                server.should_exit = True
            busy = join_until(threads, time.monotonic() + settings.shutdown_grace_s)
            if busy:
                store.stop_writes()
                log.warning("%s still busy %.1f s after the stop: stopping without their work in progress (no "
                            "write under way)", ", ".join(busy), settings.shutdown_grace_s)
    store.close()
    if not busy:
        log.info("stopped cleanly")
    return busy


def join_until(threads: Sequence[threading.Thread], deadline: float) -> list[str]:
    """Join ``threads`` until monotonic time ``deadline``; the names of those still running then."""
    for thread in threads:
        thread.join(timeout=max(0.0, deadline - time.monotonic()))
    return [thread.name for thread in threads if thread.is_alive()]


def exit_now(code: int = 0) -> NoReturn:
    """End the process at once with ``code``, its log flushed: threads that :func:`run` left busy (a stage in the
    middle of a long computation) would otherwise hold the interpreter's exit until they finish."""
    logging.shutdown()
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(code)
