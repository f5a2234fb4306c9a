"""The ``aisle`` command: subcommands do their job and bad input ends with a message, not a traceback."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

from services.cli import main
from shared.settings import get_settings
from tests.helpers import free_port


@pytest.fixture(autouse=True)
def _fresh_settings(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    monkeypatch.setenv("AISLE_DATA_DIR", str(tmp_path / "var"))
    monkeypatch.setenv("AISLE_ZENOH__LISTEN", f'["tcp/127.0.0.1:{free_port()}"]')
    get_settings.cache_clear()


def test_settings_prints_the_effective_configuration(capsys: pytest.CaptureFixture[str],
                                                     monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("AISLE_MAP_NAME", "dc-east")
    assert main(["settings"]) == 0
    printed = json.loads(capsys.readouterr().out)
    assert printed["map_name"] == "dc-east" and printed["database_url"].endswith("aisle.db")


def test_bad_settings_end_with_exit_code_2(capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("AISLE_API_PORT", "not-a-port")
    assert main(["settings"]) == 2
    assert "bad settings" in capsys.readouterr().err


def test_db_upgrade_creates_the_schema(tmp_path: Path) -> None:
    assert main(["db", "upgrade"]) == 0
    assert (tmp_path / "var" / "aisle.db").is_file()


def test_db_compact_prints_what_would_go_then_thins_and_pins_hold(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    from shared.store import MapStore, RevisionWrite

    monkeypatch.setenv("AISLE_RETENTION__KEEP_ALL_HOURS", "0")
    monkeypatch.setenv("AISLE_RETENTION__HOURLY_HOURS", "0")
    assert main(["db", "upgrade"]) == 0
    store = MapStore(f"sqlite:///{tmp_path / 'var' / 'aisle.db'}")
    site = store.ensure_map("site")
    ids = [store.write_revision(site.id, RevisionWrite("occupancy_mapping")).id for _ in range(5)]
    capsys.readouterr()

    assert main(["db", "pin", str(ids[1])]) == 0
    assert main(["db", "compact", "--dry-run"]) == 0
    assert "would drop 3 of 5 revisions (by stage: occupancy_mapping 3)" in capsys.readouterr().out
    assert [r.id for r in store.revisions(site.id)] == ids
    assert main(["db", "compact"]) == 0
    assert "dropped 3 of 5 revisions" in capsys.readouterr().out
    assert [r.id for r in store.revisions(site.id)] == [ids[1], ids[4]]
    assert main(["db", "pin", "999"]) == 2
    assert main(["db", "compact", "--map", "nowhere"]) == 2
    assert "no map named 'nowhere'" in capsys.readouterr().err
    store.close()


def test_sim_world_writes_ground_truth(tmp_path: Path) -> None:
    assert main(["sim", "world", "demo", "--out", str(tmp_path / "demo")]) == 0
    geojson = json.loads((tmp_path / "demo" / "world.geojson").read_text())
    kinds = {feature["properties"]["kind"] for feature in geojson["features"]}
    assert {"wall", "pillar", "bin", "rack_row"} <= kinds
    assert (tmp_path / "demo" / "labels.png").is_file()


def test_missing_inputs_are_reported_not_raised(tmp_path: Path) -> None:
    assert main(["map-build", str(tmp_path / "nothing"), "--out", str(tmp_path / "m.yaml")]) == 1
    assert main(["import-carmen", str(tmp_path / "nothing.log"), str(tmp_path / "out")]) == 1
    assert main(["replay", str(tmp_path / "nothing")]) == 1
    assert main(["sim", "world", "--out", str(tmp_path / "w")]) == 1  # neither a layout nor --random


def test_unknown_subcommand_exits_with_usage() -> None:
    with pytest.raises(SystemExit) as exit_info:
        main(["fly"])
    assert exit_info.value.code == 2


def test_racks_fit_turns_upright_landmarks_into_rows_and_bins(tmp_path: Path) -> None:
    assert main(["sim", "world", "demo", "--out", str(tmp_path / "demo")]) == 0
    lines = (tmp_path / "demo" / "uprights.csv").read_text().splitlines()[1:]
    landmarks = tmp_path / "pillars.csv"
    landmarks.write_text("x,y,sxx,sxy,syy\n" + "".join(
        f"{line.split(',')[1]},{line.split(',')[2]},0.0009,0,0.0009\n" for line in lines))
    assert main(["racks", "fit", str(landmarks), "--out", str(tmp_path / "racks")]) == 0
    features = json.loads((tmp_path / "racks" / "racks.geojson").read_text())["features"]
    kinds = [feature["properties"]["kind"] for feature in features]
    assert kinds.count("rack_row") >= 2 and kinds.count("bin") > 0


def test_decompose_writes_every_output(tmp_path: Path) -> None:
    assert main(["sim", "world", "demo", "--out", str(tmp_path / "demo")]) == 0
    assert main(["decompose", str(tmp_path / "demo" / "occupancy.yaml"), "--out", str(tmp_path / "dec")]) == 0
    for name in ("labels.png", "segments.png", "layout.geojson", "topology.json", "overview.png"):
        assert (tmp_path / "dec" / name).is_file()
    assert main(["decompose", str(tmp_path / "demo" / "world.geojson"), "--out", str(tmp_path / "bad")]) == 1


def test_decompose_loads_neither_the_bus_nor_the_store_and_leaves_the_collector_on(tmp_path: Path) -> None:
    # a fresh interpreter, as a user's shell starts it: what the command loads is what it pays for
    image = np.full((100, 180), 205, dtype=np.uint8)  # unknown
    image[5:95, 5:175] = 0  # walls
    image[8:92, 8:172] = 254  # free
    image[8:92, 88:91] = 0  # a wall with a door
    image[40:58, 88:91] = 254
    cv2.imwrite(str(tmp_path / "map.png"), image)
    code = ("import gc, sys\n"
            "from services.cli import main\n"
            f"code = main(['decompose', {str(tmp_path / 'map.png')!r}, '--resolution', '0.05', '--out', "
            f"{str(tmp_path / 'dec')!r}])\n"
            "print(code, sorted(m for m in ('sqlalchemy', 'zenoh') if m in sys.modules), gc.isenabled())\n")
    done = subprocess.run([sys.executable, "-c", code], cwd=Path(__file__).resolve().parents[2], capture_output=True,
                          text=True, timeout=300, check=False)
    assert done.returncode == 0, done.stderr
    assert done.stdout.split() == ["0", "[]", "True"]
    assert (tmp_path / "dec" / "segments.png").is_file()


def test_floor_plan_writes_every_output_and_prints_k(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["sim", "world", "demo", "--out", str(tmp_path / "demo")]) == 0
    capsys.readouterr()
    yaml_path = str(tmp_path / "demo" / "occupancy.yaml")
    assert main(["floor-plan", yaml_path, "--out", str(tmp_path / "fp"), "--iterations", "300"]) == 0
    assert "K(W,M)" in capsys.readouterr().out
    for name in ("floor_plan.geojson", "units.png", "rooms.png", "overview.png"):
        assert (tmp_path / "fp" / name).is_file()
    assert main(["floor-plan", str(tmp_path / "demo" / "world.geojson"), "--out", str(tmp_path / "bad")]) == 1
    track = tmp_path / "track.csv"
    track.write_text("5.0,5.0\n6.0,5.5\n")
    assert main(["floor-plan", yaml_path, "--out", str(tmp_path / "fp2"), "--iterations", "300",
                 "--trajectory", str(track)]) == 0
    track.write_text("5.0\n")
    assert main(["floor-plan", yaml_path, "--out", str(tmp_path / "fp3"), "--iterations", "300",
                 "--trajectory", str(track)]) == 1, "a trajectory without x and y is a clear error"


def test_keys_are_created_listed_and_revoked(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["keys", "create", "--role", "read", "--name", "wms"]) == 0
    key_id, _, secret = capsys.readouterr().out.strip().partition(": ")
    key_id = key_id.split()[0]
    assert secret.startswith("aisle_") and key_id in secret
    assert main(["keys", "list"]) == 0
    listed = capsys.readouterr().out
    assert key_id in listed and "wms" in listed and secret not in listed
    assert main(["keys", "revoke", key_id]) == 0
    assert main(["keys", "list"]) == 0
    assert key_id not in capsys.readouterr().out
    assert main(["keys", "revoke", "000000000000"]) == 1
