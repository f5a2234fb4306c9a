"""Bin occupancy in the store: the load-scene writer and the stock queries on a hall-sized map.

Prints ``name value unit`` lines (wall and CPU seconds). A temporary SQLite map store holds a hall of ``BAYS`` rack
bays of ``LEVELS`` levels (one bin each, as the pillar stage writes them); then the writer stores a first survey
(every bin and bay), a small update (``CHANGED`` bins of one aisle pass) with a fresh writer, a repeat of it (nothing
changed), and another update with a writer a worker keeps (it has read the stage's records before); the
queries read the bins by occupancy, one bay's scene and the discrepancies against a WMS stock list of every bin.
Run from the repository root with ``PYTHONPATH=. .venv/bin/python bench/bench_bin_occupancy.py``.
"""

from __future__ import annotations

import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from atlas.bins import select_bins
from atlas.cache import RevisionCache
from atlas.stock import bin_scene, import_wms_stock, stock_discrepancies, with_evidence
from shared.loads import (
    BinOccupancy,
    ObjectKind,
    Occupancy,
    Relation,
    SceneEdge,
    SceneGraph,
    SceneNode,
    SceneWriter,
    write_scene_revision,
)
from shared.store import Feature, MapStore, RevisionWrite, WmsStock

BAYS = 1000
LEVELS = 4
CHANGED = 40


def _timed(name: str, call: Callable[[], Any]) -> Any:
    wall, cpu = time.perf_counter(), time.process_time()
    result = call()
    print(f"{name}_wall {time.perf_counter() - wall:.4f} s")
    print(f"{name}_cpu {time.process_time() - cpu:.4f} s")
    return result


def _hall(rng: np.random.Generator) -> tuple[list[Feature], list[SceneGraph], list[BinOccupancy]]:
    bins, scenes, states = [], [], []
    for bay in range(BAYS):
        x, y, key = 2.7 * (bay % 50), 4.0 * (bay // 50), f"r{bay // 50:02d}/{bay % 50 + 1}"
        nodes, edges = [], []
        for level in range(LEVELS):
            bin_id = f"{bay // 50 + 1:02d}-{bay % 50 + 1:03d}-{level + 1:02d}"
            bins.append(Feature("bin", bin_id, {"type": "Point", "coordinates": [x, y]},
                                {"id": bin_id, "level": level, "centre": [x, y]}, 0.9))
            z = 1.5 * level
            occupied = bool(rng.random() < 0.7)
            objects: tuple[str, ...] = ()
            if occupied:
                pallet, load = f"p{level}", f"l{level}"
                nodes += [SceneNode(pallet, ObjectKind.PALLET, (x, y, z + 0.07), (1.2, 0.8, 0.14), 0.0, level),
                          SceneNode(load, ObjectKind.LOAD, (x, y, z + 0.6), (1.2, 0.8, 0.9), 0.0, level)]
                edges.append(SceneEdge(pallet, load, Relation.SUPPORTS))
                objects = (pallet, load)
            states.append(BinOccupancy(bin_id, Occupancy.OCCUPIED if occupied else Occupancy.EMPTY, 0.95,
                                       1_764_126_000_000_000_000, objects, views=3, bay=key))
        scenes.append(SceneGraph(key, tuple(nodes), tuple(edges), 1_764_126_000_000_000_000, iterations=100))
    return bins, scenes, states


def main() -> None:
    rng = np.random.default_rng(0)
    bins, scenes, states = _hall(rng)
    with tempfile.TemporaryDirectory() as tmp:
        store = MapStore(f"sqlite:///{Path(tmp) / 'bench.db'}")
        store.upgrade()
        info = store.ensure_map("hall")
        store.write_revision(info.id, RevisionWrite("pillar_mapping", features={"bin": bins}))
        print(f"bins {len(bins)} count")
        print(f"bays {len(scenes)} count")
        _timed("write_first_survey", lambda: write_scene_revision(store, info.id, scenes, states))
        changed = [BinOccupancy(s.bin_id, Occupancy.EMPTY, 0.9, s.last_seen_ns, (), 4, bay=s.bay)
                   for s in states[:CHANGED]]
        touched = sorted({s.bay for s in changed if s.bay is not None})
        bays = [scene for scene in scenes if scene.bay in touched]
        update = _timed("write_update_fresh_writer", lambda: write_scene_revision(store, info.id, bays, changed))
        print(f"write_update_bins_changed {len(update.bins_changed)} count")
        repeat = _timed("write_repeat", lambda: write_scene_revision(store, info.id, bays, changed))
        print(f"write_repeat_revision {0 if repeat.revision is None else 1} count")
        writer = SceneWriter(store, info.id)
        writer.write([], [])  # a worker's writer has read the stage's records once, at its first write
        again = [BinOccupancy(s.bin_id, Occupancy.OCCUPIED, 0.9, s.last_seen_ns, ("p0",), 5, bay=s.bay)
                 for s in changed]
        _timed("write_update_kept_writer", lambda: writer.write(bays, again))
        cache = RevisionCache()
        _timed("select_occupied", lambda: select_bins(store, cache, info.id, revision=None, bbox=None,
                                                      occupancy=Occupancy.OCCUPIED, limit=100, offset=0))
        _timed("bin_scene", lambda: bin_scene(store, cache, info, states[-1].bin_id, revision=None))
        stock = [WmsStock(s.bin_id, bool(rng.random() < 0.7)) for s in states]
        _timed("import_stock", lambda: import_wms_stock(store, info.id, stock, complete=False))
        check = _timed("discrepancies", lambda: stock_discrepancies(store, cache, info, revision=None))
        print(f"discrepancies {len(check.discrepancies)} count")
        _timed("evidence_page_1000", lambda: with_evidence(store, info, check.discrepancies[:1000], revision=None))
        store.close()


if __name__ == "__main__":
    main()
