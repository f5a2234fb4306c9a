"""Running Aisle: stage workers and the API in one process, or one stage per process."""

from __future__ import annotations

import logging
import signal
import threading
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from types import FrameType

from shared.bus import Bus
from shared.settings import STAGES, Settings
from shared.store import MapStore
from shared.worker import StageFactory, run_stage

log = logging.getLogger(__name__)


def stage_factories() -> dict[str, StageFactory]:
    """Every stage Aisle can run, by name (imported lazily: stages pull in heavy libraries).

    Each factory builds its stage from the stage's own settings section (``context.settings.<section>``).
    """
    from services.grid_decomposition.worker import decomposition_stage
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


def run(
    settings: Settings,
    *,
    stages: Sequence[str],
    api: bool,
    stop: threading.Event,
    extra: Sequence[Callable[[Bus, threading.Event], None]] = (),
    expected_workers: Sequence[str] | None = None,
) -> None:
    """Run ``stages`` (and the API if ``api``) until ``stop`` is set; then shut down cleanly.

    ``extra`` callables run in their own threads with the bus (e.g. a bag replay). The API's health check is
    degraded while a worker of ``expected_workers`` is not alive (default: ``stages``; ``aisle serve``, which runs
    none itself, expects the deployment's ``settings.stages``, each in its own process).
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
        threads += [threading.Thread(target=job, args=(bus, stop), name=getattr(job, "__name__", "job"))
                    for job in extra]
        server = None
        if api:
            import uvicorn

            from api.app import create_app
            from shared.store.keys import ensure_admin_key

            first_admin = ensure_admin_key(store)
            if first_admin is not None:
                log.warning("first admin API key, shown only now (create others with `aisle keys create`): %s",
                            first_admin)
            app = create_app(store=store, settings=settings, bus=bus,
                             expected_workers=stages if expected_workers is None else expected_workers,
                             require_keys_for_reads=settings.reads_need_key,
                             rate_limit_per_s=settings.api_rate_limit_per_s,
                             rate_limit_burst=settings.api_rate_limit_burst, cors_origins=settings.api_cors_origins,
                             event_poll_s=settings.api_event_poll_s, event_heartbeat_s=settings.api_event_heartbeat_s,
                             live_staleness_s=settings.api_live_staleness_s, key_recheck_s=settings.api_key_recheck_s)
            server = uvicorn.Server(uvicorn.Config(app, host=settings.api_host, port=settings.api_port,
                                                   log_level=settings.log_level.lower(), access_log=False))
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
            for thread in threads:
                thread.join()
    store.close()
    log.info("stopped cleanly")
