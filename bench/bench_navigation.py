"""Navigation: region-graph build, routes and the LIF / Open-RMF exports, on a small and a large warehouse.

Prints ``name value unit`` lines. The small warehouse is the simulated one of the API tests
(``tests/api/warehouse_map.py``, 31 m x 17 m, 96 bins); the large one the seeded synthetic
warehouse of the grid-decomposition tests (151 m x 61 m at 5 cm, 3.7 Mpx, about 1100 regions).
Each is decomposed once and stored in a temporary SQLite map store; routes join random pairs of
free drivable cells (seeded). Run from the repository root with
``PYTHONPATH=. .venv/bin/python bench/bench_navigation.py``.
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

import numpy as np

from atlas.cache import RevisionCache
from atlas.exports.lif import lif_document
from atlas.exports.rmf import rmf_nav_graph
from atlas.navigation import NoRouteError, load_navmap, plan_route
from services.grid_decomposition import decompose
from services.grid_decomposition.records import decomposition_layers, decomposition_topology
from shared.store import GridLayer, MapInfo, MapStore, RevisionWrite
from tests.api.warehouse_map import write_warehouse
from tests.services.grid_decomposition.warehouse import synthetic_warehouse

ROUTES = 200


def _large(store: MapStore) -> MapInfo:
    wh = synthetic_warehouse(0, n_double_rows=10, n_sections=4, bays_per_section=12)
    info = store.ensure_map("large")
    occupancy = GridLayer("occupancy", wh.occupancy, wh.resolution_m, 0.0, 0.0)
    store.write_revision(info.id, RevisionWrite("occupancy_mapping", layers=[occupancy]))
    result = decompose(wh.occupancy, resolution_m=wh.resolution_m)
    store.write_revision(info.id, RevisionWrite("grid_decomposition", layers=decomposition_layers(result),
                                                topology=decomposition_topology(result)))
    return info


def _bench(name: str, store: MapStore, info: MapInfo) -> None:
    cache = RevisionCache()
    start = time.perf_counter()
    nav = load_navmap(store, info.id, cache=cache)
    cold = time.perf_counter() - start
    start = time.perf_counter()
    nav = load_navmap(store, info.id, cache=cache)
    warm = time.perf_counter() - start
    print(f"{name}.cells {nav.grid.segments.size} cells")
    print(f"{name}.regions {len(nav.regions)} regions")
    print(f"{name}.portals {len(nav.grid.portals)} portals")
    print(f"{name}.navmap_cold {cold * 1000:.0f} ms")
    print(f"{name}.navmap_warm {warm * 1000:.1f} ms")
    rng = np.random.default_rng(0)
    rows, cols = np.nonzero(nav.drivable_mask)
    picks = rng.integers(0, rows.size, size=(ROUTES, 2))
    times, failed, vias = [], 0, 0
    for a, b in picks:
        p = nav.frame.centre(float(rows[a]), float(cols[a]))
        q = nav.frame.centre(float(rows[b]), float(cols[b]))
        start = time.perf_counter()
        try:
            route = plan_route(nav, p, q)
            vias += sum(w.kind == "via" for w in route.waypoints)
        except NoRouteError:
            failed += 1
        times.append(time.perf_counter() - start)
    print(f"{name}.route_median {np.median(times) * 1000:.1f} ms")
    print(f"{name}.route_p95 {np.percentile(times, 95) * 1000:.1f} ms")
    print(f"{name}.route_unreachable {failed / ROUTES * 100:.1f} %")
    print(f"{name}.route_via_points {vias / ROUTES:.2f} per_route")
    start = time.perf_counter()
    document = lif_document(store, info, None)
    print(f"{name}.lif_export {(time.perf_counter() - start) * 1000:.0f} ms")
    layout = document["layouts"][0]
    print(f"{name}.lif_nodes {len(layout['nodes'])} nodes")
    print(f"{name}.lif_edges {len(layout['edges'])} edges")
    print(f"{name}.lif_stations {len(layout['stations'])} stations")
    start = time.perf_counter()
    rmf_nav_graph(store, info, None)
    print(f"{name}.rmf_export {(time.perf_counter() - start) * 1000:.0f} ms")


def main() -> None:
    with tempfile.TemporaryDirectory() as folder:
        store = MapStore(f"sqlite:///{Path(folder) / 'bench.db'}")
        store.upgrade()
        _bench("small", store, write_warehouse(store, map_name="small"))
        _bench("large", store, _large(store))
        store.close()


if __name__ == "__main__":
    main()
