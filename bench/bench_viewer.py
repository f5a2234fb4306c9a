"""The map viewer in a real headless Chromium: first paint of the 250 m x 72 m hall and what an update costs.

Prints ``name value unit`` lines. The simulated hall's ground truth (5 cm occupancy and place labels of 5053 x 1499
cells, about 12,800 features with 8,910 bins) is written to a SQLite store in a temporary folder and served by the
API (uvicorn on loopback, in this process). Chromium (Debian's ``chromium`` and ``chromium-driver``) opens the
viewer ``REPEATS`` times: first paint is from navigation start to the frame after every layer is drawn (the page's
own clock), with the bytes it fetched; the first after the server starts (its live state and layer pictures not
yet built) is reported apart. Then one bin moves in a new revision: the time until the page shows it,
and the bytes that update fetched. Then the bins canvas redraw (what a pan or zoom costs) at two zooms.
With ``--screenshots DIR`` it also writes pictures of the viewer there: on ``aisle run --demo`` (its simulated
robot mapping the demo warehouse), on a replayed log with ``--replay BAG``, and on the hall.
CPU time is this process's (the API, the store and the driver), the browser's is not counted.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import signal
import socket
import statistics
import subprocess
import sys
import tempfile
import threading
import time
import urllib.request
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import uvicorn

from api import create_app
from services.grid_decomposition.overview import LABEL_COLOURS
from services.simulator import ground_truth_features, ground_truth_grids, load_world
from shared.settings import Settings
from shared.store import Feature, GridLayer, MapStore, RevisionWrite
from shared.vocabulary import PlaceLabel

REPEATS = 3
CHROMIUM, CHROMEDRIVER = "/usr/bin/chromium", "/usr/bin/chromedriver"
WINDOW = (1600, 900)
BYTES = "return performance.getEntriesByType('resource').reduce((n, e) => n + (e.transferSize || e.encodedBodySize), 0)"


def world_store(url: str, layout: str) -> MapStore:
    """A store holding the ground truth of simulator world ``layout`` as map ``site`` (one revision)."""
    store = MapStore(url)
    store.upgrade()
    world = load_world(layout, seed=0)
    grids = ground_truth_grids(world)
    geometry = (grids.resolution_m, grids.origin_x_m, grids.origin_y_m)
    labels_meta = {"encoding": "place_labels", "classes": [label.name.lower() for label in PlaceLabel],
                   "colours": [list(LABEL_COLOURS[label]) for label in PlaceLabel]}
    features: dict[str, list[Feature]] = {}
    for item in ground_truth_features(world)["features"]:
        properties = dict(item["properties"])
        kind = properties.pop("kind")
        features.setdefault(kind, []).append(Feature(kind, str(properties["id"]), item["geometry"], properties,
                                                     0.9 if kind == "bin" else None))
    map_id = store.ensure_map("site").id
    store.write_revision(map_id, RevisionWrite("truth", layers=[
        GridLayer("occupancy", grids.occupancy, *geometry, {"encoding": "occupancy"}),
        GridLayer("place_labels", grids.labels, *geometry, labels_meta),
    ], features=features))
    return store


@contextmanager
def serving(store: MapStore, folder: Path) -> Iterator[str]:
    app = create_app(store=store, settings=Settings(data_dir=folder, database_url=store.url), event_poll_s=0.1,
                     rate_limit_per_s=None)
    port = free_port()
    server = uvicorn.Server(uvicorn.Config(app, host="127.0.0.1", port=port, log_level="warning",
                                           timeout_graceful_shutdown=1))
    thread = threading.Thread(target=server.run, daemon=True)
    thread.start()
    while not server.started:
        time.sleep(0.02)
    try:
        yield f"http://127.0.0.1:{port}"
    finally:
        server.should_exit = True
        thread.join(timeout=20)


def free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


@contextmanager
def chromium() -> Iterator[Any]:
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    options = webdriver.ChromeOptions()
    options.binary_location = CHROMIUM
    for argument in ("--headless=new", "--no-sandbox", "--disable-dev-shm-usage", "--disable-gpu",
                     f"--window-size={WINDOW[0]},{WINDOW[1]}", "--force-device-scale-factor=1"):
        options.add_argument(argument)
    driver = webdriver.Chrome(service=Service(CHROMEDRIVER), options=options)
    try:
        yield driver
    finally:
        driver.quit()


def wait(driver: Any, script: str, timeout_s: float = 120.0) -> Any:
    deadline = time.monotonic() + timeout_s
    while not (value := driver.execute_script(script)):
        if time.monotonic() > deadline:
            raise TimeoutError(script)
        time.sleep(0.01)
    return value


def first_paint(driver: Any, url: str) -> tuple[float, int]:
    """Seconds from navigation to the first frame with every layer drawn, and the bytes fetched for it."""
    driver.get("about:blank")
    driver.get(url)
    ready_ms = wait(driver, "return window.aisleViewer && window.aisleViewer.readyAt")
    return ready_ms / 1000.0, int(driver.execute_script(BYTES))


def update(driver: Any, store: MapStore) -> tuple[float, int]:
    """Move one bin in a new revision; seconds from its commit until the page shows it, and the bytes it fetched."""
    info = store.get_map("site")
    assert info is not None
    bins = [item.feature for item in store.features(info.id, kinds=["bin"])]
    first = bins[0]
    ring = [[x + 0.05, y] for x, y in first.geometry["coordinates"][0]]
    bins[0] = Feature("bin", first.key, {"type": "Polygon", "coordinates": [ring]}, first.properties, first.confidence)
    driver.execute_script("performance.clearResourceTimings()")
    revision = store.write_revision(info.id, RevisionWrite("truth", features={"bin": bins})).id
    start = time.perf_counter()  # from the commit
    wait(driver, f"return document.getElementById('revision-id').textContent === '{revision}'")
    return time.perf_counter() - start, int(driver.execute_script(BYTES))


def redraw_ms(driver: Any) -> float:
    return float(driver.execute_script(
        "const b = window.aisleViewer.groups.bins, t = performance.now();"
        "for (let i = 0; i < 20; i++) b.redraw(); return (performance.now() - t) / 20"))


@contextmanager
def aisle_run(folder: Path, *args: str) -> Iterator[str]:
    """``aisle run ARGS`` (every stage and the API) in its own process with its own data folder; yields the API's
    URL."""
    port = free_port()
    env = {**os.environ, "AISLE_DATA_DIR": str(folder / "run"), "AISLE_API_PORT": str(port),
           "AISLE_ZENOH__LISTEN": f'["tcp/127.0.0.1:{free_port()}"]', "AISLE_OCCUPANCY__STORE_PERIOD_S": "1"}
    shutil.rmtree(folder / "run", ignore_errors=True)
    with (folder / "run.log").open("w") as log:
        process = subprocess.Popen([sys.executable, "-m", "services.cli", "run", *args],
                                   env=env, stdout=log, stderr=subprocess.STDOUT)
        try:
            yield f"http://127.0.0.1:{port}"
        finally:
            process.send_signal(signal.SIGINT)
            process.wait(timeout=120)


def get_json(url: str) -> Any:
    try:
        with urllib.request.urlopen(url, timeout=5) as response:
            return json.load(response)
    except (OSError, ValueError):
        return None


def screenshots(folder: Path, out: Path, bag: Path | None) -> None:
    """Pictures of the viewer into ``out``: on ``aisle run --demo`` once its robot has mapped some racks, on
    ``aisle run --replay BAG`` once the log is through (with ``bag``), and on the hall."""
    out.mkdir(parents=True, exist_ok=True)
    demo = ("--demo", "--demo-rate", "3")
    run_screenshot(folder, out / "viewer_demo.png", demo, lambda url: len(
        (get_json(url + "/v1/maps/site/layout?kind=bin") or {"features": []})["features"]) >= 40)
    if bag is not None:
        run_screenshot(folder, out / "viewer_replay.png", ("--replay", str(bag), "--rate", "4"),
                       lambda url: _scans(url) >= 340)
    hall_screenshot(folder, out)


def _scans(url: str) -> int:
    health = get_json(url + "/v1/health") or {"workers": []}
    workers = {w["name"]: w for w in health["workers"]}
    counters = workers.get("occupancy_mapping", {}).get("counters", {})
    return int(counters.get("occupancy_mapping.scans_integrated", 0))


def run_screenshot(folder: Path, out: Path, args: tuple[str, ...], done: Callable[[str], bool]) -> None:
    """A picture of the viewer on ``aisle run ARGS`` once ``done(url)`` (or after 5 minutes)."""
    with aisle_run(folder, *args) as url:
        deadline = time.monotonic() + 300
        while time.monotonic() < deadline and not done(url):
            time.sleep(2)
        with chromium() as driver:
            driver.get(url + "/")
            wait(driver, "return window.aisleViewer && window.aisleViewer.readyAt")
            time.sleep(1.0)
            driver.save_screenshot(str(out))
            driver.get("about:blank")
    print(f"screenshot {out}")


def hall_screenshot(folder: Path, out: Path) -> None:
    """The viewer on the hall, zoomed in on a bin found by its id (its card open)."""
    store = world_store(f"sqlite:///{folder / 'hall_shots.db'}", "hall")
    with serving(store, folder) as url, chromium() as driver:
        driver.get(url + "/")
        wait(driver, "return window.aisleViewer && window.aisleViewer.readyAt")
        ids = driver.execute_script("return window.aisleViewer.groups.bins.ids().sort()")
        driver.find_element("id", "bin-query").send_keys(ids[40] + "\n")
        wait(driver, f"return document.getElementById('card-title').textContent === 'Bin {ids[40]}'")
        time.sleep(1.5)  # the flight to the bin
        driver.execute_script("const m = window.aisleViewer.leaflet; m.setZoom(4.5, {animate: false});")
        time.sleep(0.5)
        driver.save_screenshot(str(out / "viewer_hall.png"))
    store.close()
    print(f"screenshot {out / 'viewer_hall.png'}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--screenshots", type=Path, help="write pictures of the viewer into this folder")
    parser.add_argument("--replay", type=Path, help="with --screenshots: a rosbag2 to replay for a picture too")
    args = parser.parse_args()
    if shutil.which(CHROMIUM) is None or shutil.which(CHROMEDRIVER) is None:
        print(f"skipped: no {CHROMIUM} or {CHROMEDRIVER} (apt-get install chromium chromium-driver)")
        return
    print(f"load_average_1min {os.getloadavg()[0]:.1f}")
    with tempfile.TemporaryDirectory() as name:
        folder = Path(name)
        start = time.perf_counter()
        store = world_store(f"sqlite:///{folder / 'hall.db'}", "hall")
        info = store.get_map("site")
        assert info is not None
        print(f"hall_bins {len(store.features(info.id, kinds=['bin']))} count")
        print(f"hall_features {len(store.features(info.id))} count")
        print(f"hall_store_written {time.perf_counter() - start:.1f} s")
        with serving(store, folder) as url, chromium() as driver:
            cpu = time.process_time()
            cold = first_paint(driver, url + "/")
            print(f"first_paint_cold_server {cold[0]:.2f} s")
            print(f"first_paint_cold_server_cpu {time.process_time() - cpu:.2f} s")
            cpu = time.process_time()
            paints = [first_paint(driver, url + "/") for _ in range(REPEATS)]
            print(f"first_paint_best {min(p[0] for p in paints):.2f} s")
            print(f"first_paint_median {statistics.median(p[0] for p in paints):.2f} s")
            print(f"first_paint_server_cpu {(time.process_time() - cpu) / REPEATS:.2f} s")
            print(f"first_paint_bytes {paints[0][1] / 1e6:.2f} MB")
            updates = [update(driver, store) for _ in range(REPEATS)]
            print(f"update_one_bin_moved_shown_after {statistics.median(u[0] for u in updates):.2f} s")
            print(f"update_one_bin_moved_bytes {statistics.median(u[1] for u in updates) / 1e3:.1f} kB")
            print(f"bins_redraw_whole_hall {redraw_ms(driver):.1f} ms")
            driver.execute_script("window.aisleViewer.leaflet.setZoom(4, {animate: false})")
            print(f"bins_redraw_zoomed_in_with_ids {redraw_ms(driver):.1f} ms")
        store.close()
        if args.screenshots:
            screenshots(folder, args.screenshots, args.replay)
    print(f"load_average_1min {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
