"""The composition root's own duties: the first admin key, shown so nobody misses it."""

from __future__ import annotations

import logging
from pathlib import Path

import pytest

from services.runtime import announce_first_admin_key
from shared.store import MapStore
from shared.store.keys import Role, verify_key


def test_the_first_admin_key_is_shown_once_in_a_box(tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    store = MapStore(f"sqlite:///{tmp_path / 'aisle.db'}")
    store.upgrade()

    with caplog.at_level(logging.INFO):
        secret = announce_first_admin_key(store)
        shown = [r for r in caplog.records if r.levelno >= logging.WARNING]
        caplog.clear()
        again = announce_first_admin_key(store)

    assert secret is not None and again is None and caplog.records == []
    (record,) = shown
    lines = record.getMessage().splitlines()
    framed = [line for line in lines if line.startswith("#") and line.endswith("#")]
    assert framed == lines[1:] and len({len(line) for line in framed}) == 1  # a closed box of one width
    assert any(line.strip("# ") == secret for line in framed)
    found = verify_key(store, secret=secret)
    assert found is not None and found.role == Role.ADMIN
    store.close()
