"""Running one stage worker the way ``aisle worker`` does, for integration tests."""

from __future__ import annotations

import threading
from collections.abc import Iterator
from contextlib import contextmanager

from shared.bus import Bus
from shared.settings import Settings
from shared.store import MapStore
from shared.worker import StageFactory, run_stage
from tests.helpers import wait_for


@contextmanager
def running_stage(name: str, factory: StageFactory, settings: Settings, store: MapStore) -> Iterator[Bus]:
    """Stage ``name`` under :func:`run_stage` on a bus opened from ``settings``; yields that bus.

    Waits until the worker announces itself (its subscriptions are then declared) and, on exit,
    until it has stopped cleanly.
    """
    stop = threading.Event()
    with Bus.open(settings.zenoh, domain_id=settings.ros_domain_id) as bus:
        thread = threading.Thread(target=run_stage, args=(name, factory),
                                  kwargs={"bus": bus, "store": store, "settings": settings, "stop": stop})
        thread.start()
        try:
            wait_for(lambda: bus.alive_workers() == [name], what=f"the {name} worker to come up")
            yield bus
        finally:
            stop.set()
            thread.join(timeout=60)
            assert not thread.is_alive(), f"{name} did not stop"
