"""How well the occupancy map built from the real mac_first_floor bag lines up with the bag's own map.

Builds the map from ../shared/data/bags/mac_first_floor/bag with odometry alone and with scan
matching, registers each onto mac_1st_floor_final.pgm and prints ``name value unit`` lines:
reference wall cells within 0.1 m of ours (all, and those in the area the bag saw) and our wall
cells within 0.1 m of the reference's.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

from services.occupancy_mapping import ScanMatcher, build_map, sharpness, wall_agreement
from shared.mapfiles import read_map_yaml
from shared.store import GridLayer

DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "bags" / "mac_first_floor"


def main() -> int:
    if not DATA.exists():
        print(f"skipped: {DATA} is not present", file=sys.stderr)
        return 0
    reference = read_map_yaml(DATA / "mac_1st_floor_final.yaml")
    ref_layer = GridLayer("reference", reference.occupancy, reference.resolution_m, reference.origin_x_m,
                          reference.origin_y_m)
    for name, corrector in (("odometry", None), ("scan_matching", ScanMatcher(max_range_m=30.0))):
        start = time.perf_counter()
        grid = build_map(DATA / "bag", resolution_m=0.05, corrector=corrector)
        built_s = time.perf_counter() - start
        agreement = wall_agreement(grid.to_layer("ours"), ref_layer, tolerance_m=0.1)
        print(f"mac_{name}_build_time {built_s:.2f} s")
        print(f"mac_{name}_reference_walls_within_0.1m {agreement.fraction:.3f} fraction")
        print(f"mac_{name}_reference_walls_in_view_within_0.1m {agreement.fraction_in_view:.3f} fraction")
        print(f"mac_{name}_our_walls_within_0.1m_of_reference {agreement.precision:.3f} fraction")
        print(f"mac_{name}_sharpness {sharpness(grid.occupancy()):.3f} score")
    return 0


if __name__ == "__main__":
    sys.exit(main())
