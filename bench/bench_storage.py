"""How fast the store grows under `aisle run --demo`, without and with retention.

Run: ``PYTHONPATH=. .venv/bin/python bench/bench_storage.py [--minutes 4] [--modes keep,thin]``. Each mode runs
``aisle run --demo`` (one simulated robot, all default stages, SQLite in a temporary folder) for ``--minutes`` and
samples the database every 15 s. Prints ``name value unit`` lines per mode:

* ``<mode>.revisions_per_min``: revisions the stages stored;
* ``<mode>.growth_mb_per_h``: growth of the data in the file (pages in use, WAL checkpointed or not), fitted over
  the second half of the run, so the first minutes of mapping an empty hall weigh less;
* ``<mode>.db_mb``: pages in use at the end; ``<mode>.cpu_s``: CPU time of the `aisle run` process.

Modes: ``keep`` compacts never (as before retention existed); ``thin`` keeps every revision of the last
``--keep-all-min`` minutes and compacts every ``--compact-period-s`` (as the defaults do with 6 h and 1 h), so its
growth is what a site sees once the keep-everything window is full.
"""

from __future__ import annotations

import argparse
import os
import signal
import socket
import sqlite3
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

_SAMPLE_S = 15.0
_CLOCK_TICKS = os.sysconf("SC_CLK_TCK")


def _free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


def _used(path: Path) -> tuple[int, int]:
    """Bytes of the pages in use (the WAL's newest pages count) and the number of revisions."""
    if not path.exists():
        return 0, 0
    with sqlite3.connect(f"file:{path}?mode=ro", uri=True, timeout=30) as db:
        pages, free, size = (db.execute(f"PRAGMA {p}").fetchone()[0]
                             for p in ("page_count", "freelist_count", "page_size"))
        try:
            revisions = db.execute("SELECT count(*) FROM revisions").fetchone()[0]
        except sqlite3.OperationalError:  # not migrated yet
            revisions = 0
    return (pages - free) * size, revisions


def _cpu_s(pid: int) -> float:
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / _CLOCK_TICKS


def run_mode(mode: str, *, minutes: float, keep_all_min: float, compact_period_s: float) -> dict[str, float]:
    with tempfile.TemporaryDirectory() as folder:
        db = Path(folder) / "aisle.db"
        env = {**os.environ, "AISLE_DATABASE_URL": f"sqlite:///{db}", "AISLE_API_PORT": str(_free_port()),
               "AISLE_ZENOH__LISTEN": f'["tcp/127.0.0.1:{_free_port()}"]', "AISLE_LOG_LEVEL": "WARNING"}
        if mode == "thin":
            env |= {"AISLE_RETENTION__KEEP_ALL_HOURS": str(keep_all_min / 60),
                    "AISLE_RETENTION__COMPACT_PERIOD_S": str(compact_period_s)}
        else:
            env |= {"AISLE_RETENTION__COMPACT_PERIOD_S": "0"}
        process = subprocess.Popen([sys.executable, "-c", "import sys; from services.cli import main; "
                                    "sys.exit(main(sys.argv[1:]))", "run", "--demo"], env=env)
        samples: list[tuple[float, int, int]] = []
        start = time.monotonic()
        try:
            while (elapsed := time.monotonic() - start) < minutes * 60:
                time.sleep(_SAMPLE_S)
                samples.append((elapsed + _SAMPLE_S, *_used(db)))
            cpu = _cpu_s(process.pid)
        finally:
            process.send_signal(signal.SIGINT)
            process.wait(timeout=60)
    t, used, revisions = (np.array(column, dtype=float) for column in zip(*samples, strict=True))
    half = t >= t[-1] / 2
    slope = np.polyfit(t[half], used[half], 1)[0] if half.sum() >= 2 else float("nan")
    figures = {"growth_mb_per_h": slope * 3600 / 1e6, "db_mb": used[-1] / 1e6, "revisions_kept": revisions[-1],
               "cpu_s": cpu}
    return {"revisions_per_min": revisions[-1] / (t[-1] / 60), **figures} if mode == "keep" else figures


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--minutes", type=float, default=4.0)
    parser.add_argument("--modes", default="keep,thin")
    parser.add_argument("--keep-all-min", type=float, default=1.0)
    parser.add_argument("--compact-period-s", type=float, default=30.0)
    args = parser.parse_args()
    for mode in args.modes.split(","):
        figures = run_mode(mode, minutes=args.minutes, keep_all_min=args.keep_all_min,
                           compact_period_s=args.compact_period_s)
        for name, value in figures.items():
            unit = {"revisions_per_min": "/min", "growth_mb_per_h": "MB/h", "db_mb": "MB", "cpu_s": "s"}.get(name, "")
            print(f"{mode}.{name} {value:.2f} {unit}".rstrip(), flush=True)
    print(f"load {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
