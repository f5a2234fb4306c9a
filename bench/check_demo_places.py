"""The place layer of the demo as a user gets it: ``aisle run --demo`` for a few minutes, then asked over HTTP.

Checks the criteria of issue 20 ("one map, not two") against the demo world's ground truth and prints each with its
figures as ``name value`` lines, then ``PASS``/``FAIL`` per criterion:

* ``aisles``: every true aisle (the strip between two facing rack rows, one per aisle and rack section) lies mostly
  in one corridor region, and that region is named after the pillar stage's aisle (``aisle: aisle-NN`` on its
  feature);
* ``bins``: every bin answers (``GET …/bins/{id}``) a storage region, its aisle's corridor, a drivable region at its
  access pose and a nearest junction;
* ``crossings``: every aisle end and every crossing of an aisle and a cross aisle lies mostly in a junction region;
* ``cross_aisles``: no cross aisle (the gap between two rack sections, about one bay wide) is bridged into
  storage (under 5 % of its labelled cells);
* ``no_room``: no ``room`` region anywhere in the hall;
* ``open_floor``: no storage over open floor: storage-labelled cells farther than ``--tolerance`` from every true
  rack row less its cross aisles (the unmapped strip between the top row and the wall once was storage).

With ``--url`` it asks a stack that runs already (``--revision``: about an older revision); else it starts
``aisle run --demo`` itself (own data folder under /tmp, free ports), asks it after each of ``--at`` seconds (a key
check: the aisles' region keys are the same at every check) and stops it. Exits 1 when a criterion fails at the
last check.

    PYTHONPATH=. .venv/bin/python bench/check_demo_places.py                 # 5 minutes of demo
    PYTHONPATH=. .venv/bin/python bench/check_demo_places.py --at 180 300
    PYTHONPATH=. .venv/bin/python bench/check_demo_places.py --url http://127.0.0.1:8000
"""

from __future__ import annotations

import argparse
import io
import os
import signal
import socket
import subprocess
import sys
import tempfile
import time
import urllib.error
import urllib.request
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import numpy.typing as npt

from services.simulator import ground_truth_features, load_world

MAP = "/v1/maps/site"
REGION_KINDS = ("corridor", "junction", "room", "open_area", "region")
STORAGE = 3  # place_labels code


@dataclass(frozen=True)
class Grid:
    data: npt.NDArray[Any]
    resolution_m: float
    origin_xy_m: tuple[float, float]

    def mask(self, rings: list[npt.NDArray[np.float64]]) -> npt.NDArray[np.bool_]:
        """Cells whose centres the polygons (map metres) cover."""
        out = np.zeros(self.data.shape, np.uint8)
        shift = 4
        cells = [np.round(((ring - self.origin_xy_m) / self.resolution_m - 0.5) * (1 << shift)).astype(np.int32)
                 for ring in rings]
        cv2.fillPoly(out, cells, 1, cv2.LINE_8, shift)
        return out > 0


class Api:
    def __init__(self, url: str) -> None:
        self.url = url.rstrip("/")

    def raw(self, path: str, **params: Any) -> bytes:
        query = "&".join(f"{k}={v}" for k, values in params.items()
                         for v in (values if isinstance(values, list | tuple) else [values]))
        for _ in range(50):
            try:
                with urllib.request.urlopen(f"{self.url}{path}{'?' + query if query else ''}", timeout=30) as answer:
                    body: bytes = answer.read()
                    return body
            except urllib.error.HTTPError as err:
                if err.code != 429:  # rate limited: wait and ask again
                    raise
                time.sleep(0.5)
        raise RuntimeError(f"{path}: still rate limited")

    def json(self, path: str, **params: Any) -> Any:
        import json

        return json.loads(self.raw(path, **params))

    def grid(self, layer: str, revision: int) -> Grid:
        meta = self.json(f"{MAP}/layers/{layer}", revision=revision)
        data = np.load(io.BytesIO(self.raw(f"{MAP}/layers/{layer}/values", revision=revision, format="npy")),
                       allow_pickle=False)
        return Grid(data, float(meta["resolution_m"]), (float(meta["origin"]["x_m"]), float(meta["origin"]["y_m"])))


def _ring(feature: dict[str, Any]) -> npt.NDArray[np.float64]:
    return np.asarray(feature["geometry"]["coordinates"][0], dtype=np.float64)


def check(api: Api, truth: dict[str, list[dict[str, Any]]], *, tolerance_m: float, revision: int | None = None
          ) -> dict[str, Any]:
    """Every criterion's figures at ``revision`` (default: the map's newest); ``passed`` per criterion (``bins``:
    every bin the pillar stage has answers in full; ``bins`` against ``truth_bins`` says whether it has all)."""
    revision = int(api.json(f"{MAP}")["latest_revision_id"]) if revision is None else revision
    layout = api.json(f"{MAP}/layout", kind=[*REGION_KINDS, "rack_row", "bin"], revision=revision)["features"]
    regions = {f["properties"]["region_id"]: f for f in layout
               if f["properties"].get("stage") == "grid_decomposition" and f["properties"]["kind"] in REGION_KINDS}
    pillar_aisles = {f["properties"]["key"] for f in layout
                     if f["properties"]["kind"] == "corridor" and f["properties"].get("stage") == "pillar_mapping"}
    segments, labels = api.grid("place_segments", revision), api.grid("place_labels", revision)
    out: dict[str, Any] = {"revision": revision, "regions": len(regions),
                           "rack_rows": sum(f["properties"]["kind"] == "rack_row"
                                            and f["properties"].get("source") == "pillar_mapping" for f in layout),
                           "pillar_aisles": len(pillar_aisles), "truth_bins": len(truth["bin"])}
    # aisles: the region holding most of each true aisle's labelled cells
    named, aisle_keys = 0, {}
    shares = []
    for aisle in (c for c in truth["corridor"] if c["properties"].get("corridor_kind") == "aisle"):
        cells = segments.data[segments.mask([_ring(aisle)]) & (segments.data > 0)]
        ids, counts = np.unique(cells, return_counts=True)
        best = int(ids[counts.argmax()]) if counts.size else 0
        share = float(counts.max() / counts.sum()) if counts.size else 0.0
        props = regions.get(best, {}).get("properties", {})
        want = f"aisle-{aisle['properties']['aisle']:02d}"
        ok = props.get("label") == "corridor" and props.get("aisle") == want and share > 0.5
        named += ok
        shares.append(share)
        aisle_keys[aisle["properties"]["id"]] = props.get("key")
        print(f"aisle {aisle['properties']['id']} {want}: region {props.get('key')} {props.get('label')} "
              f"aisle={props.get('aisle')} holds {100 * share:.1f} % of it", flush=True)
    true_aisles = len(shares)
    out.update(aisles_named=named, aisles=true_aisles, aisle_min_share=min(shares, default=0.0), aisle_keys=aisle_keys)
    # crossings and cross aisles
    held = []
    for junction in truth["junction"]:
        cells = segments.data[segments.mask([_ring(junction)]) & (segments.data > 0)]
        best = int(np.bincount(cells.astype(np.int64)).argmax()) if cells.size else 0
        held.append(regions.get(best, {}).get("properties", {}).get("label") == "junction")
    out.update(crossings_junction=sum(held), crossings=len(held))
    cross = [c for c in truth["corridor"] if c["properties"].get("corridor_kind") == "cross_aisle"]
    bridged = []
    for piece in cross:
        codes = labels.data[labels.mask([_ring(piece)]) & (labels.data > 0)]
        bridged.append(float((codes == STORAGE).mean()) if codes.size else 0.0)
    out.update(cross_aisles_storage=sum(b >= 0.05 for b in bridged), cross_aisles=len(bridged),
               cross_aisle_worst_storage_share=round(max(bridged, default=0.0), 3))
    # bins: every bin's answer
    bins = api.json(f"{MAP}/bins", limit=1000, revision=revision)["bins"]
    missing = {"storage_region": 0, "corridor": 0, "region": 0, "nearest_junction": 0, "aisle_corridor": 0}
    for listed in bins:
        answer = api.json(f"{MAP}/bins/{listed['id']}", revision=revision)
        storage = answer.get("storage_region") or {}
        missing["storage_region"] += storage.get("label") != "storage"
        missing["corridor"] += answer.get("corridor") is None
        missing["aisle_corridor"] += (answer.get("corridor") or {}).get("key") != f"aisle-{answer['aisle']:02d}"
        missing["region"] += (answer.get("region") or {}).get("label") not in ("corridor", "junction")
        missing["nearest_junction"] += answer.get("nearest_junction") is None
    out["bins"] = len(bins)
    out.update({f"bins_without_{k}": v for k, v in missing.items()})
    # rooms
    rooms = [f["properties"]["key"] for f in regions.values() if f["properties"].get("label") == "room"]
    out["rooms"] = len(rooms)
    # storage over open floor: storage cells beyond tolerance_m of every true rack row
    racks = labels.mask([_ring(r) for r in truth["rack_row"]]) & ~labels.mask([_ring(c) for c in cross])
    grow = 2 * round(tolerance_m / labels.resolution_m) + 1
    near = cv2.dilate(racks.astype(np.uint8), np.ones((grow, grow), np.uint8)) > 0
    stray = (labels.data == STORAGE) & ~near
    cell_m2 = labels.resolution_m ** 2
    out["storage_m2"] = round(float((labels.data == STORAGE).sum()) * cell_m2, 2)
    out["storage_off_racks_m2"] = round(float(stray.sum()) * cell_m2, 2)
    labelled = labels.data[racks & (labels.data > 0)]  # free cells of the true racks (labels are on free cells)
    out["storage_recall"] = round(float((labelled == STORAGE).mean()) if labelled.size else 0.0, 4)
    worst = np.bincount(segments.data[stray].astype(np.int64)) if stray.any() else np.zeros(1, np.int64)
    out["storage_off_racks_worst_region"] = (f"r{int(worst.argmax())} {worst.max() * cell_m2:.2f} m2"
                                             if worst.max() else "-")
    out["passed"] = {
        "aisles": named == true_aisles > 0,
        "bins": bool(bins) and not any(missing.values()),
        "crossings": all(held),
        "cross_aisles": not out["cross_aisles_storage"],
        "no_room": not rooms,
        "open_floor": out["storage_off_racks_m2"] == 0.0,
    }
    return out


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@contextmanager
def demo(folder: Path) -> Iterator[str]:
    """``aisle run --demo`` on free ports with its own data folder; stopped with SIGINT."""
    port = _free_port()
    env = {**os.environ, "AISLE_DATA_DIR": str(folder), "AISLE_API_PORT": str(port),
           "AISLE_ZENOH__LISTEN": f'["tcp/127.0.0.1:{_free_port()}"]'}
    with (folder / "aisle.log").open("w") as log:
        process = subprocess.Popen([sys.executable, "-m", "services.cli", "run", "--demo"], env=env, stdout=log,
                                   stderr=subprocess.STDOUT)
        try:
            yield f"http://127.0.0.1:{port}"
        finally:
            process.send_signal(signal.SIGINT)
            try:
                process.wait(timeout=60)
            except subprocess.TimeoutExpired:
                process.kill()
                process.wait()


def _truth(world: str) -> dict[str, list[dict[str, Any]]]:
    out: dict[str, list[dict[str, Any]]] = {}
    for feature in ground_truth_features(load_world(world))["features"]:
        out.setdefault(str(feature["properties"]["kind"]), []).append(feature)
    return out


def report(api: Api, truth: dict[str, list[dict[str, Any]]], *, tolerance_m: float, label: str,
           revision: int | None = None) -> dict[str, Any]:
    figures = check(api, truth, tolerance_m=tolerance_m, revision=revision)
    for name, value in figures.items():
        if name != "passed":
            print(f"{label} {name} {value}", flush=True)
    for name, ok in figures["passed"].items():
        print(f"{label} {'PASS' if ok else 'FAIL'} {name}", flush=True)
    return figures


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--url", help="ask this running stack instead of starting the demo")
    parser.add_argument("--at", type=float, nargs="+", default=[300.0],
                        help="seconds after the start at which to check (default 300)")
    parser.add_argument("--revision", type=int, help="with --url: the revision to check (default: the newest)")
    parser.add_argument("--world", default="demo", help="the world the stack maps (ground truth)")
    parser.add_argument("--tolerance", type=float, default=0.15,
                        help="storage this close to a true rack row is not open floor, metres")
    args = parser.parse_args()
    truth = _truth(args.world)
    if args.url:
        figures = report(Api(args.url), truth, tolerance_m=args.tolerance, label="now", revision=args.revision)
        return 0 if all(figures["passed"].values()) else 1
    with tempfile.TemporaryDirectory(prefix="aisle-demo-") as folder, demo(Path(folder)) as url:
        start, api, runs = time.monotonic(), Api(url), []
        for at in sorted(args.at):
            time.sleep(max(0.0, start + at - time.monotonic()))
            runs.append(report(api, truth, tolerance_m=args.tolerance, label=f"t{at:.0f}s"))
        keys = [run["aisle_keys"] for run in runs]
        stable = all(k == keys[0] for k in keys)
        print(f"aisle_region_keys_stable {stable}")
        return 0 if all(runs[-1]["passed"].values()) and stable else 1


if __name__ == "__main__":
    sys.exit(main())
