"""Settings come from AISLE_* variables and an optional TOML file, and refuse nonsense early."""

from __future__ import annotations

from pathlib import Path

import pytest
from pydantic import ValidationError

from shared.settings import Settings


def test_defaults_are_an_isolated_embedded_stack(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("AISLE_CONFIG_FILE", raising=False)
    settings = Settings()
    assert settings.database_url == "sqlite:///var/aisle.db"
    assert settings.zenoh.mode == "peer" and not settings.zenoh.multicast_scouting
    assert all(endpoint.startswith("tcp/127.0.0.1") for endpoint in settings.zenoh.listen)
    assert (settings.api_host, settings.api_port) == ("127.0.0.1", 8000)
    assert settings.robot_namespaces == ["*"]


def test_environment_and_nested_groups(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("AISLE_ROS_DOMAIN_ID", "42")
    monkeypatch.setenv("AISLE_ROBOT_NAMESPACES", '["/robot1/", "fleet/agv_2"]')
    monkeypatch.setenv("AISLE_OCCUPANCY__RESOLUTION_M", "0.1")
    monkeypatch.setenv("AISLE_ZENOH__CONNECT", '["tcp/10.0.0.5:7447"]')
    settings = Settings()
    assert settings.ros_domain_id == 42
    assert settings.robot_namespaces == ["robot1", "fleet/agv_2"]
    assert settings.occupancy.resolution_m == 0.1
    assert settings.zenoh.connect == ["tcp/10.0.0.5:7447"]


def test_config_file_is_read_and_environment_wins(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    config = tmp_path / "aisle.toml"
    config.write_text('map_name = "dc-east"\napi_port = 9000\n[occupancy]\nresolution_m = 0.025\n')
    monkeypatch.setenv("AISLE_CONFIG_FILE", str(config))
    monkeypatch.setenv("AISLE_API_PORT", "9100")
    settings = Settings()
    assert (settings.map_name, settings.api_port, settings.occupancy.resolution_m) == ("dc-east", 9100, 0.025)


def test_missing_config_file_is_a_clear_error(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("AISLE_CONFIG_FILE", "/nonexistent/aisle.toml")
    with pytest.raises(FileNotFoundError, match="AISLE_CONFIG_FILE"):
        Settings()


@pytest.mark.parametrize(("variable", "value"), [
    ("AISLE_ROS_DOMAIN_ID", "300"),
    ("AISLE_DATABASE_URL", "mysql://x"),
    ("AISLE_ZENOH__MODE", "broker"),
    ("AISLE_ZENOH__LISTEN", '["127.0.0.1:7447"]'),
    ("AISLE_OCCUPANCY__RESOLUTION_M", "-1"),
    ("AISLE_ROBOT_NAMESPACES", '["robot 1"]'),
])
def test_nonsense_fails_fast(variable: str, value: str, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv(variable, value)
    with pytest.raises(ValidationError):
        Settings()


def test_aisle_run_starts_only_known_stages(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("AISLE_STAGES", '["occupancy_mapping", "object_labelling"]')
    assert Settings().stages == ["occupancy_mapping", "object_labelling"]
    monkeypatch.setenv("AISLE_STAGES", '["occupancy_mapping", "teleportation"]')
    with pytest.raises(ValidationError, match="unknown stages"):
        Settings()


def test_reads_need_a_key_once_the_api_leaves_loopback(monkeypatch: pytest.MonkeyPatch) -> None:
    assert Settings().reads_need_key is False
    monkeypatch.setenv("AISLE_API_HOST", "0.0.0.0")
    assert Settings().reads_need_key is True
    monkeypatch.setenv("AISLE_API_REQUIRE_KEYS_FOR_READS", "false")
    assert Settings().reads_need_key is False
