"""Stages without robot traffic sleep: each waits for its input in long stretches instead of polling."""

from __future__ import annotations

import threading
import time
from pathlib import Path

import pytest

from services.runtime import stage_factories
from shared.bus import Bus, Subscription
from shared.settings import Settings, ZenohSettings
from shared.store import MapStore
from shared.worker import run_stage
from tests.helpers import wait_for

WINDOW_S = 1.5
"""How long an idle stage is watched."""
LEAST_WAIT_S = 0.25
"""An idle stage must wait at least this long, on average, between two looks at its inputs (it polled every
0.05 s: twenty wake-ups a second, per stage, with nothing to do)."""


@pytest.mark.parametrize("stage", ["occupancy_mapping", "pillar_mapping", "semantic_fusion"])
def test_a_stage_without_traffic_waits_for_input_instead_of_polling(
        stage: str, zenoh_listen: ZenohSettings, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    idle_waits: list[float] = []  # when each wait of the stage's thread that found nothing ended
    receive = Subscription.receive

    def counted(self: Subscription, timeout: float = 0.0) -> object:
        item = receive(self, timeout)
        if item is None and timeout > 0 and threading.current_thread().name == stage:
            idle_waits.append(time.monotonic())
        return item

    monkeypatch.setattr(Subscription, "receive", counted)
    settings = Settings(data_dir=tmp_path, zenoh=zenoh_listen)
    store = MapStore(settings.database_url)
    store.upgrade()
    stop = threading.Event()
    with Bus.open(settings.zenoh, domain_id=settings.ros_domain_id) as bus:
        worker = threading.Thread(target=run_stage, name=stage, args=(stage, stage_factories()[stage]),
                                  kwargs={"bus": bus, "store": store, "settings": settings, "stop": stop})
        worker.start()
        try:
            wait_for(lambda: bool(idle_waits), timeout_s=120, what=f"{stage} waiting for input")
            start = idle_waits[0]
            wait_for(lambda: time.monotonic() - start >= WINDOW_S, timeout_s=WINDOW_S + 5, what="the window")
            looks = sum(start < t <= start + WINDOW_S for t in idle_waits)
        finally:
            stop.set()
            worker.join(timeout=30)
    store.close()
    assert looks <= WINDOW_S / LEAST_WAIT_S, f"{stage} looked at its inputs {looks} times in {WINDOW_S} s idle"
