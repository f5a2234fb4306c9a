"""``aisle run`` thins old revisions by itself, every ``retention.compact_period_s``."""

from __future__ import annotations

import threading
from pathlib import Path

from services.runtime import compact_periodically
from shared.settings import RetentionSettings, Settings
from shared.store import MapStore, RevisionWrite
from tests.helpers import wait_for


def test_periodic_compaction_thins_old_revisions_until_stopped(tmp_path: Path) -> None:
    settings = Settings(data_dir=tmp_path, retention=RetentionSettings(keep_all_hours=0, hourly_hours=0,
                                                                       compact_period_s=0.05))
    store = MapStore(settings.database_url)
    store.upgrade()
    site = store.ensure_map("site")
    ids = [store.write_revision(site.id, RevisionWrite("occupancy_mapping")).id for _ in range(4)]
    stop = threading.Event()
    worker = threading.Thread(target=compact_periodically, args=(store, settings, stop))
    worker.start()
    try:
        wait_for(lambda: len(store.revisions(site.id)) == 1, what="the old revisions thinned")
        assert [r.id for r in store.revisions(site.id)] == ids[-1:]
    finally:
        stop.set()
        worker.join(timeout=5)
        store.close()
    assert not worker.is_alive()
