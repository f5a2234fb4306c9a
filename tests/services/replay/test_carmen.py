"""CARMEN FLASER logs into rosbag2."""

from __future__ import annotations

import gzip
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from rosbags.highlevel import AnyReader

from services.occupancy_mapping import build_map_with_stats
from services.replay.carmen import CarmenError, beam_layout, import_carmen
from shared.messages import LASER_SCAN, ODOMETRY, TYPESTORE
from shared.transforms import yaw_from_quaternion

DATA = Path(__file__).resolve().parents[4] / "shared" / "data"


def _log_lines(n_scans: int, seed: int = 11) -> tuple[list[str], np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    ranges = np.round(rng.uniform(0.5, 10.0, (n_scans, 180)), 3)
    ranges[:, 5] = 81.91  # no return
    poses = np.column_stack([np.arange(n_scans) * 0.1, np.zeros(n_scans), np.linspace(-3.0, 3.0, n_scans)])
    lines = [
        "# message formats defined: PARAM SYNC ODOM FLASER",
        "PARAM robot_use_laser on nohost 0",
        "ODOM 0 0 0 0 0 0 0.1 pippo 0.1",
    ]
    for i in range(n_scans):
        x, y, th = poses[i]
        body = " ".join(f"{r:.3f}" for r in ranges[i])
        lines.append(f"FLASER 180 {body} {x} {y} {th} {x} {y} {th} {10 + i * 0.2} pippo {10 + i * 0.2}")
    return lines, ranges, poses


@pytest.mark.parametrize("storage", ["mcap", "sqlite3"])
def test_import_round_trips_ranges_poses_and_stamps(tmp_path: Path, storage: str) -> None:
    lines, ranges, poses = _log_lines(6)
    lines.insert(5, "FLASER 180 1.0 2.0 oops")
    log = tmp_path / "small.log.gz"
    with gzip.open(log, "wt") as stream:
        stream.write("\n".join(lines) + "\n")
    result = import_carmen(log, tmp_path / "bag", storage=storage, namespace="robot1")  # type: ignore[arg-type]
    assert (result.scans, result.malformed_lines, result.repaired_stamps) == (6, 1, 0)
    scans: list[tuple[int, Any]] = []
    odoms: list[Any] = []
    with AnyReader([tmp_path / "bag"], default_typestore=TYPESTORE) as reader:
        assert {c.topic for c in reader.connections} == {
            "/robot1/scan",
            "/robot1/odom",
            "/robot1/tf",
            "/robot1/tf_static",
        }
        for conn, ns, raw in reader.messages():
            msg = reader.deserialize(raw, conn.msgtype)
            if conn.msgtype == LASER_SCAN:
                scans.append((ns, msg))
            elif conn.msgtype == ODOMETRY:
                odoms.append(msg)
    assert [ns for ns, _ in scans] == [round((10 + i * 0.2) * 1e9) for i in range(6)]
    first = scans[0][1]
    assert first.header.frame_id == "laser"
    assert first.angle_min == pytest.approx(-math.pi / 2)
    assert first.angle_increment == pytest.approx(math.pi / 180)
    expected = ranges[0].astype(np.float32)
    expected[5] = np.inf
    np.testing.assert_array_equal(first.ranges, expected)
    for msg, pose in zip(odoms, poses, strict=True):
        assert (msg.header.frame_id, msg.child_frame_id) == ("odom", "base_link")
        assert msg.pose.pose.position.x == pytest.approx(pose[0])
        assert yaw_from_quaternion(
            [
                msg.pose.pose.orientation.x,
                msg.pose.pose.orientation.y,
                msg.pose.pose.orientation.z,
                msg.pose.pose.orientation.w,
            ]
        ) == pytest.approx(pose[2])
    _, stats = build_map_with_stats(tmp_path / "bag", scan_topic="scan")
    assert stats.scans_integrated == 6


def test_import_repairs_stamps_that_do_not_increase(tmp_path: Path) -> None:
    lines, _, _ = _log_lines(3)
    lines = [line.replace(" 10.2 pippo", " 0 pippo") for line in lines]
    (tmp_path / "a.log").write_text("\n".join(lines))
    assert import_carmen(tmp_path / "a.log", tmp_path / "bag", storage="sqlite3").repaired_stamps == 1


@pytest.mark.parametrize(
    ("n", "angle_min", "increment_deg"), [(180, -90, 1.0), (181, -90, 1.0), (361, -90, 0.5)]
)
def test_beam_layout_follows_carmen_convention(n: int, angle_min: float, increment_deg: float) -> None:
    start, step = beam_layout(n)
    assert (math.degrees(start), math.degrees(step)) == pytest.approx((angle_min, increment_deg))


def test_import_rejects_unreadable_and_empty_logs(tmp_path: Path) -> None:
    with pytest.raises(CarmenError, match="does not exist"):
        import_carmen(tmp_path / "missing.log", tmp_path / "bag")
    (tmp_path / "bad.log.gz").write_bytes(b"not gzip at all")
    with pytest.raises(CarmenError, match="not readable"):
        import_carmen(tmp_path / "bad.log.gz", tmp_path / "bag")
    (tmp_path / "empty.log").write_text("ODOM 0 0 0 0 0 0 1 pippo 1\nFLASER 3 1 2\n")
    with pytest.raises(CarmenError, match=r"no usable FLASER lines \(1 malformed\)"):
        import_carmen(tmp_path / "empty.log", tmp_path / "bag")


def test_import_refuses_to_overwrite_a_bag(tmp_path: Path) -> None:
    lines, _, _ = _log_lines(2)
    (tmp_path / "a.log").write_text("\n".join(lines))
    (tmp_path / "bag").mkdir()
    with pytest.raises(CarmenError, match="cannot write bag"):
        import_carmen(tmp_path / "a.log", tmp_path / "bag")


@pytest.mark.skipif(
    not (DATA / "logs" / "radish").is_dir(), reason="shared data folder ../shared/data absent"
)
def test_orebro_log_imports_and_maps(tmp_path: Path) -> None:
    result = import_carmen(DATA / "logs" / "radish" / "orebro-corrected.log.gz", tmp_path / "bag")
    assert result.scans == 237 and result.malformed_lines == 0
    grid, stats = build_map_with_stats(tmp_path / "bag", resolution_m=0.1)
    assert stats.scans_integrated == 237
    assert np.count_nonzero(grid.occupancy() > 65) > 1000
