"""Every JSON answer carries metres to the millimetre and angles to 4 decimals, whichever path serves it (live from
memory, read at a revision, GeoJSON layout, exports), never 15 decimals."""

from __future__ import annotations

import json
from collections.abc import Iterator
from typing import Any

from fastapi.testclient import TestClient

from shared.bins import AccessPose, Bin
from shared.store import Feature, MapStore, RevisionWrite

URL = "/v1/maps/hall"
LONG = 1.0 / 3.0
"""A float with 16 decimals; added to every coordinate written."""


def _floats(document: Any, key: str = "") -> Iterator[tuple[str, float]]:
    """(name it goes under, value) of every float in a JSON document."""
    if isinstance(document, float):
        yield key, document
    elif isinstance(document, dict):
        for name, value in document.items():
            yield from _floats(value, name)
    elif isinstance(document, list):
        for value in document:
            yield from _floats(value, key)


def _decimals(value: float) -> int:
    text = repr(value)
    return 0 if "." not in text or "e" in text else len(text.split(".")[1])


def test_every_answer_rounds_metres_to_millimetres_and_angles_to_four_decimals(client: TestClient,
                                                                              store: MapStore) -> None:
    map_id = store.ensure_map("hall").id
    record = Bin(id="01-002-01", centre=(6.37 + LONG, 6.05 + LONG), aisle=1, bay=2, level=0, z_m=LONG,
                 footprint=((6 + LONG, 5.5), (7 + LONG, 5.5), (7 + LONG, 6.6), (6 + LONG, 6.6), (6 + LONG, 5.5)),
                 access_pose=AccessPose(6.5 + LONG, 4.0 + LONG, -1.5707963267948966), confidence=0.9 + LONG / 10)
    row = Feature("rack_row", "r0-001", {"type": "LineString", "coordinates": [[LONG, LONG], [27 + LONG, LONG]]},
                  {"kind": "rack_row", "theta": 0.0123456789, "d": 2.7 + LONG / 100})
    revision = store.write_revision(map_id, RevisionWrite("pillar_mapping", features={
        "bin": [record.feature()], "rack_row": [row]})).id
    paths = [f"{URL}/bins/01-002-01", f"{URL}/bins/01-002-01?revision={revision}", f"{URL}/bins",
             f"{URL}/features", f"{URL}/features?revision={revision}", f"{URL}/layout", f"{URL}/exports/geojson",
             f"{URL}/semantics?x=6.5&y=6"]

    served = {path: json.loads(client.get(path).content) for path in paths}

    for path, body in served.items():
        values = list(_floats(body))
        assert values, path
        for name, value in values:
            angle = name.endswith("_rad") or name in {"theta", "access_pose"}
            assert _decimals(value) <= (4 if angle else 3), f"{path}: {name} = {value!r}"
    one = served[f"{URL}/bins/01-002-01"]
    assert one["centre"] == [6.703, 6.383] and one["access_pose"]["yaw_rad"] == -1.5708
    assert one == served[f"{URL}/bins/01-002-01?revision={revision}"]
