"""docker-compose.yml runs real ``aisle`` commands with real settings (no docker engine needed)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from pathlib import Path
from typing import Any

import httpx2 as httpx
import pytest
import yaml
from pydantic import BaseModel

from services.cli import _parser
from shared.bus import Bus
from shared.settings import STAGES, Settings, ZenohSettings
from tests.helpers import free_port, wait_for
from tests.stack import answers, health

COMPOSE = Path(__file__).resolve().parents[1] / "docker-compose.yml"


def _services() -> dict[str, Any]:
    services: dict[str, Any] = yaml.safe_load(COMPOSE.read_text())["services"]
    return services


def _aisle_services() -> dict[str, Any]:
    return {name: svc for name, svc in _services().items() if svc.get("image", "").startswith("aisle")}


def _setting_exists(variable: str) -> bool:
    path = variable.removeprefix("AISLE_").lower().split("__")
    model: type[BaseModel] = Settings
    for part in path[:-1]:
        field = model.model_fields.get(part)
        if field is None or not (isinstance(field.annotation, type) and issubclass(field.annotation, BaseModel)):
            return False
        model = field.annotation
    return path[-1] in model.model_fields


def test_every_stage_has_its_own_container() -> None:
    commands = [svc["command"] for svc in _aisle_services().values()]
    for stage in STAGES:
        assert ["worker", stage] in commands


@pytest.mark.parametrize("name", sorted(_aisle_services()))
def test_service_runs_a_real_aisle_subcommand(name: str) -> None:
    command = _aisle_services()[name]["command"]
    _parser().parse_args(command)  # exits (SystemExit) on anything aisle does not know


@pytest.mark.parametrize("name", sorted(_aisle_services()))
def test_service_uses_only_real_settings(name: str, monkeypatch: pytest.MonkeyPatch) -> None:
    environment = {k: str(v) for k, v in _aisle_services()[name].get("environment", {}).items()}
    unknown = [k for k in environment if k.startswith("AISLE_") and not _setting_exists(k)]
    assert unknown == []
    for key, value in environment.items():
        monkeypatch.setenv(key, value)
    settings = Settings()
    assert settings.database_url.startswith("postgresql")


def test_workers_reach_the_router_and_the_database() -> None:
    services = _services()
    assert "zenoh" in services and "postgres" in services
    for svc in _aisle_services().values():
        env = svc["environment"]
        assert "postgres:5432" in env["AISLE_DATABASE_URL"]
        if svc["command"][0] != "db":
            assert env["AISLE_ZENOH__CONNECT"] == '["tcp/zenoh:7447"]'


def test_the_api_expects_every_worker_compose_runs(monkeypatch: pytest.MonkeyPatch) -> None:
    api = _aisle_services()["api"]
    for key, value in api["environment"].items():
        monkeypatch.setenv(key, str(value))
    workers = {svc["command"][1] for svc in _aisle_services().values() if svc["command"][0] == "worker"}
    assert set(Settings().stages) == workers


def test_serve_reports_the_configured_workers_missing_until_they_are_up(tmp_path: Path) -> None:
    zenoh, port = f"tcp/127.0.0.1:{free_port()}", free_port()
    env = {**{k: v for k, v in os.environ.items() if not k.startswith("AISLE_")},
           "AISLE_DATA_DIR": str(tmp_path), "AISLE_API_PORT": str(port), "AISLE_ZENOH__LISTEN": f'["{zenoh}"]',
           "AISLE_STAGES": '["occupancy_mapping", "pillar_mapping"]'}
    with (tmp_path / "serve.log").open("w") as log:
        serve = subprocess.Popen([sys.executable, "-m", "services.cli", "serve"], env=env, stdout=log,
                                 stderr=subprocess.STDOUT, cwd=Path(__file__).resolve().parents[1])
        try:
            with httpx.Client(base_url=f"http://127.0.0.1:{port}", timeout=5) as client, \
                    Bus.open(ZenohSettings(listen=[], connect=[zenoh]), domain_id=0) as worker_bus:
                wait_for(lambda: answers(client), timeout_s=60, what="aisle serve to answer")
                assert health(client)["missing_workers"] == ["occupancy_mapping", "pillar_mapping"]
                assert client.get("/v1/health").status_code == 503
                tokens = [worker_bus.declare_worker(name) for name in ("occupancy_mapping", "pillar_mapping")]
                wait_for(lambda: health(client)["status"] == "ok", timeout_s=10, what="both workers seen alive")
                for token in tokens:
                    token.undeclare()
            serve.send_signal(signal.SIGINT)
            assert serve.wait(timeout=30) == 0
        finally:
            if serve.poll() is None:
                serve.kill()
