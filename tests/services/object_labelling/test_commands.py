"""The ``aisle`` commands around the stage: no start without a usable model, one command to train one."""

from __future__ import annotations

import logging
from pathlib import Path

import pytest

from services.cli import main
from shared.settings import get_settings
from tests.helpers import free_port


@pytest.fixture(autouse=True)
def _fresh_settings(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    monkeypatch.setenv("AISLE_DATA_DIR", str(tmp_path / "var"))
    monkeypatch.setenv("AISLE_ZENOH__LISTEN", f'["tcp/127.0.0.1:{free_port()}"]')
    get_settings.cache_clear()


@pytest.mark.parametrize("content", [None, b"PK\x03\x04 truncated", b"not a model at all"])
def test_worker_and_run_stop_before_starting_without_a_usable_model(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture, content: bytes | None
) -> None:
    if content is not None:
        (tmp_path / "var").mkdir()
        (tmp_path / "var" / "object_labelling.npz").write_bytes(content)
    with caplog.at_level(logging.ERROR):
        assert main(["worker", "object_labelling"]) == 1
    assert "aisle train-classifier" in caplog.text
    assert ("does not exist" if content is None else "corrupt") in caplog.text
    monkeypatch.setenv("AISLE_STAGES", '["occupancy_mapping", "object_labelling"]')
    get_settings.cache_clear()
    caplog.clear()
    with caplog.at_level(logging.ERROR):
        assert main(["run"]) == 1
    assert "aisle train-classifier" in caplog.text
