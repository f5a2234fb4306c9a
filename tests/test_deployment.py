"""docker-compose.yml runs real ``aisle`` commands with real settings (no docker engine needed)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest
import yaml
from pydantic import BaseModel

from services.cli import _parser
from shared.settings import STAGES, Settings

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
