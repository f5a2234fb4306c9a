"""Hashes of many decompositions, to show that a change leaves every output as it was.

Run in each checkout and compare the two files::

    PYTHONPATH=. .venv/bin/python bench/decomposition_hashes.py run OUT.json [--sets rose2 partial ipa racks hall]
    PYTHONPATH=. .venv/bin/python bench/decomposition_hashes.py diff A.json B.json

Per output it hashes the segments, the labels, the region records, the topology (edges with their
attributes), the rack rows, the texture regions, the face image and the face labels; the partial
ubremen steps are decomposed with the previous step as prior and keyed as ``eval_ipa.py`` does it
(their keyed segment layer is hashed too). Sets: the ROSE\u00b2 full maps, the 15 partial steps, the ipa
maps plain and furnished, the 42 rack halls of ``bench_grid_decomposition.py --racks-only`` and the
250 m hall.
"""

from __future__ import annotations

import argparse
import hashlib
import json
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
from threadpoolctl import threadpool_limits

from bench import bench_grid_decomposition as grid_bench
from bench import eval_ipa
from services.grid_decomposition import Decomposition, decompose
from services.grid_decomposition.evaluation import FREE_GREY, align_offset
from services.grid_decomposition.keys import NEXT_ID_KEY, carry_keys, region_prior
from services.grid_decomposition.mapfile import read_map_file
from services.grid_decomposition.records import decomposition_layers
from services.simulator.rackmaps import rack_hall_map
from shared.collector import collector_held
from shared.heap import keep_freed_memory
from shared.settings import get_settings
from shared.store import GridLayer

SETS = ("rose2", "partial", "ipa", "racks", "hall")


def _digest(*parts: Any) -> str:
    h = hashlib.sha256()
    for part in parts:
        if isinstance(part, np.ndarray):
            h.update(str((part.dtype, part.shape)).encode())
            h.update(np.ascontiguousarray(part).tobytes())
        else:
            h.update(repr(part).encode())
    return h.hexdigest()[:16]


def _decompose(occupancy: npt.NDArray[np.int8], **kwargs: Any) -> Decomposition:
    """``decompose`` as the product calls it (``aisle decompose``, the worker): the cyclic collector held off."""
    with collector_held():
        return decompose(occupancy, **kwargs)


def hashes(d: Decomposition) -> dict[str, str]:
    """One hash per part of a decomposition."""
    edges = sorted((min(a, b), max(a, b), sorted(attrs.items())) for a, b, attrs in d.topology.edges(data=True))
    fl = d.face_labels
    return {
        "segments": _digest(d.segments),
        "labels": _digest(d.labels),
        "regions": _digest(sorted(d.regions.items())),
        "topology": _digest(sorted(d.topology.nodes), edges),
        "racks": _digest(d.rack_rows_px),
        "texture": _digest(d.texture_regions),
        "faces": _digest(d.subdivision.face_image),
        "face_labels": _digest(fl.evidence, fl.category, fl.label),
    }


def _outputs(sets: list[str]) -> Iterator[tuple[str, dict[str, str]]]:
    if "rose2" in sets:
        for folder in sorted(p for p in (eval_ipa.ROSE2 / "full").iterdir() if p.is_dir()):
            occ = eval_ipa.rose2_occupancy(eval_ipa._grey(folder / "map.png"))
            yield f"rose2/{folder.name}", hashes(_decompose(occ, resolution_m=0.05))
    if "partial" in sets:
        yield from _partial()
    if "ipa" in sets:
        names = sorted(p.name.removesuffix("_gt_segmentation.png") for p in eval_ipa.IPA.glob("*_gt_segmentation.png"))
        for variant in ("", "_furnitures"):
            for name in names:
                path = eval_ipa.IPA / f"{name}{variant}.png"
                if path.exists():
                    occ = read_map_file(path, resolution_m=0.05)[0]
                    yield f"ipa/{name}{variant}", hashes(_decompose(occ, resolution_m=0.05))
    if "racks" in sets:
        for style_name, style in grid_bench.RACK_SETS.items():
            for seed in (0, 1, 2):
                for turned in (False, True):
                    hall = rack_hall_map(seed, style=style, rotation_rad=0.2 + 0.16 * seed if turned else 0.0)
                    yield (f"racks/{style_name}{'_turned' if turned else ''}_{seed}",
                           hashes(_decompose(hall.occupancy, resolution_m=hall.resolution_m)))
    if "hall" in sets:
        hall = grid_bench.big_rack_hall()
        yield "hall/250m", hashes(_decompose(hall.occupancy, resolution_m=hall.resolution_m))


def _partial() -> Iterator[tuple[str, dict[str, str]]]:
    """The partial ubremen steps with prior and keys, as ``eval_ipa.py --sets partial`` runs them."""
    steps = sorted((p for p in (eval_ipa.ROSE2 / "partial_ubremen").iterdir() if p.is_dir()),
                   key=lambda p: int(p.name[3:]))
    previous: tuple[GridLayer, GridLayer, npt.NDArray[np.bool_]] | None = None
    corner = np.zeros(2, dtype=np.int64)
    for folder in steps:
        grey = eval_ipa._grey(folder / "map.png")
        free_px = grey >= FREE_GREY
        if previous is not None:
            offset = align_offset(previous[2], free_px)
            corner += [grey.shape[0] - offset[0] - previous[2].shape[0], offset[1]]
        occupancy = GridLayer("occupancy", eval_ipa.rose2_occupancy(grey), 0.05, float(-corner[1] * 0.05),
                              float(-corner[0] * 0.05))
        prior = None if previous is None else region_prior(previous[0], previous[1], occupancy)
        result, ids = carry_keys(
            _decompose(occupancy.data, resolution_m=0.05, origin_xy_m=(occupancy.origin_x_m, occupancy.origin_y_m),
                       prior=prior),
            None if previous is None else previous[0])
        layer = decomposition_layers(result, meta={NEXT_ID_KEY: ids.next_id})[1]
        yield f"partial/{folder.name}", {**hashes(result), "keyed": _digest(layer.data)}
        previous = (layer, occupancy, free_px)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = parser.add_subparsers(dest="command", required=True)
    run = sub.add_parser("run")
    run.add_argument("out", type=Path)
    run.add_argument("--sets", nargs="*", default=list(SETS), choices=SETS)
    diff = sub.add_parser("diff")
    diff.add_argument("a", type=Path)
    diff.add_argument("b", type=Path)
    args = parser.parse_args()
    if args.command == "run":
        keep_freed_memory(get_settings().heap_kept_bytes)  # as the aisle command runs every stage
        result: dict[str, dict[str, str]] = {}
        with threadpool_limits(1):
            for name, h in _outputs(args.sets):
                result[name] = h
                print(name, " ".join(h.values()), flush=True)
        args.out.write_text(json.dumps(result, indent=1))
        return
    a, b = json.loads(args.a.read_text()), json.loads(args.b.read_text())
    differ = sorted(k for k in a.keys() & b.keys() if a[k] != b[k])
    for k in differ:
        print(k, [part for part in a[k] if a[k][part] != b[k].get(part)])
    print(f"{len(a.keys() & b.keys())} outputs compared, {len(differ)} differ; "
          f"only in A: {len(a.keys() - b.keys())}, only in B: {len(b.keys() - a.keys())}")


if __name__ == "__main__":
    main()
