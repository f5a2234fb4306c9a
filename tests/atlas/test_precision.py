"""Numbers served as JSON are rounded once, by what they are: metres to the millimetre, angles to 0.1 mrad."""

from __future__ import annotations

import json
import math

from atlas.precision import json_bytes, rounded


def test_metres_round_to_the_millimetre_and_angles_to_four_decimals() -> None:
    document = {"centre": (41.199999999999996, 17.600000000000001), "yaw_rad": math.pi / 2, "theta": 0.123456789,
                "access_pose": [1.23456789, -2.00049, 3.14159265], "nested": [{"x": 1 / 3, "d_m": 2.7000000001}],
                "count": 7, "name": "x", "flag": True, "none": None}

    out = rounded(document)

    assert out == {"centre": [41.2, 17.6], "yaw_rad": 1.5708, "theta": 0.1235,
                   "access_pose": [1.235, -2.0, 3.1416], "nested": [{"x": 0.333, "d_m": 2.7}],
                   "count": 7, "name": "x", "flag": True, "none": None}


def test_non_finite_numbers_become_null_and_the_json_is_strict() -> None:
    text = json_bytes({"a": float("nan"), "b": [float("inf"), 1.0004]})

    assert json.loads(text) == {"a": None, "b": [None, 1.0]}
