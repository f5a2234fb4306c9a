"""Layout picture and export speed on the 250 m x 72 m simulated hall (5 cm grid, 5053 x 1499 cells).

Prints ``name value unit`` lines. The hall's ground truth (occupancy, place labels and about 12 800
features: 8910 bins, 3696 pillars, rows, corridors, junctions, walls, docks, chargers, objects) is
written to a SQLite store in a temporary folder; then each step is timed, best of ``REPEATS``: the
store read, the scene, PNG and SVG drawing at several widths, and whole requests through the API
(in-process TestClient, so no network).
"""

from __future__ import annotations

import tempfile
import time
from collections.abc import Callable
from functools import partial
from pathlib import Path

from fastapi.testclient import TestClient

from api import create_app
from atlas.exports import ExportOptions, export_map
from atlas.render.png import render_png
from atlas.render.scene import layout_scene
from atlas.render.svg import render_svg
from services.grid_decomposition.overview import LABEL_COLOURS
from services.simulator import ground_truth_features, ground_truth_grids, load_world
from shared.settings import Settings
from shared.store import Feature, GridLayer, MapStore, RevisionWrite
from shared.vocabulary import PlaceLabel

REPEATS = 5
WIDTHS_PX = (1024, 2048, 4096)


def _best_s(work: Callable[[], object]) -> float:
    times = []
    for _ in range(REPEATS):
        start = time.perf_counter()
        work()
        times.append(time.perf_counter() - start)
    return min(times)


def _hall_store(url: str) -> MapStore:
    store = MapStore(url)
    store.upgrade()
    world = load_world("hall", seed=0)
    grids = ground_truth_grids(world)
    geometry = (grids.resolution_m, grids.origin_x_m, grids.origin_y_m)
    labels_meta = {"encoding": "place_labels", "classes": [label.name.lower() for label in PlaceLabel],
                   "colours": [list(LABEL_COLOURS[label]) for label in PlaceLabel]}
    features: dict[str, list[Feature]] = {}
    for item in ground_truth_features(world)["features"]:
        properties = dict(item["properties"])
        kind = properties.pop("kind")
        features.setdefault(kind, []).append(Feature(kind, str(properties["id"]), item["geometry"], properties))
    map_id = store.ensure_map("site").id
    store.write_revision(map_id, RevisionWrite("truth", layers=[
        GridLayer("occupancy", grids.occupancy, *geometry),
        GridLayer("place_labels", grids.labels, *geometry, labels_meta),
    ], features=features))
    return store


def main() -> None:
    with tempfile.TemporaryDirectory() as folder:
        store = _hall_store(f"sqlite:///{Path(folder) / 'hall.db'}")
        info = store.get_map("site")
        assert info is not None
        found = store.features(info.id)
        occupancy = store.layer(info.id, "occupancy")
        labels = store.layer(info.id, "place_labels")
        assert occupancy is not None and labels is not None
        print(f"hall_features {len(found)} count")
        print(f"hall_grid_cells {occupancy.layer.data.size} cells")
        print(f"store_read_features {_best_s(lambda: store.features(info.id)):.3f} s")
        print(f"store_read_layers {_best_s(lambda: store.layer(info.id, 'occupancy')):.3f} s")
        features = [item.feature for item in found]
        for width in WIDTHS_PX:
            scene = partial(layout_scene, features, occupancy=occupancy.layer, place_labels=labels.layer, bbox=None,
                            width_px=width, title="hall")
            built = scene()
            print(f"scene_{width}px {_best_s(scene):.3f} s")
            print(f"png_draw_{width}px {_best_s(partial(render_png, built)):.3f} s")
            print(f"svg_write_{width}px {_best_s(partial(render_svg, built)):.3f} s")
            print(f"png_size_{width}px {len(render_png(built)) / 1e6:.2f} MB")
            print(f"svg_size_{width}px {len(render_svg(built)) / 1e6:.2f} MB")
        for name in ("map_server", "geojson"):
            export = partial(export_map, store, info, name, revision=occupancy.revision_id,
                             options=ExportOptions("hall"))
            print(f"export_{name} {_best_s(export):.3f} s")
        settings = Settings(data_dir=Path(folder), database_url=store.url)
        with TestClient(create_app(store=store, settings=settings, rate_limit_per_s=None)) as client:
            for path in ("/v1/maps/site/layout", "/v1/maps/site/layout.png", "/v1/maps/site/layout.svg",
                         "/v1/maps/site/layout.png?bbox=100,20,130,40", "/v1/maps/site/exports/map_server"):
                assert client.get(path).status_code == 200, path
                name = path.removeprefix("/v1/maps/site/").replace("?", "_").replace("=", "_").replace(",", "_")
                print(f"request_{name} {_best_s(partial(client.get, path)):.3f} s")
        store.close()


if __name__ == "__main__":
    main()
