"""The precision of every number Aisle serves as JSON: metres to the millimetre, angles to 0.1 mrad.

Map computations run in float64 and would serve 15 decimals (``41.199999999999996``); a WMS needs
millimetres. :func:`rounded` rounds a JSON-able document once, by the name each value goes under:
angles (``*_rad``, ``theta``, ``yaw``, the third value of an ``[x, y, yaw]`` pose such as
``access_pose``) to :data:`DECIMALS_RAD`, every other float (metres, seconds, probabilities 0..1) to
:data:`DECIMALS`. JSON has no NaN or infinity: non-finite floats come out null. :func:`json_bytes`
encodes a document so; the API's JSON responses, GeoJSON features, layout and exports all go
through it.

Examples
--------
>>> rounded({"centre": [41.199999999999996, 17.6000000001], "yaw_rad": 1.5707963267948966})
{'centre': [41.2, 17.6], 'yaw_rad': 1.5708}
>>> rounded({"access_pose": [1.23456, 2.0, 3.14159265]})
{'access_pose': [1.235, 2.0, 3.1416]}
"""

from __future__ import annotations

import json
import math
from typing import Any

DECIMALS = 3
"""Decimals of metres (a millimetre), seconds (a millisecond) and every other float that is not an angle."""
DECIMALS_RAD = 4
"""Decimals of angles in radians (0.1 mrad: 0.5 mm at 5 m)."""
ANGLE_KEYS = frozenset({"theta", "yaw", "angle", "heading"})
"""Names of angles besides those ending in ``_rad``."""
POSE_KEYS = frozenset({"access_pose", "approach_pose", "pose"})
"""Names of ``[x, y, yaw]`` poses (metres, metres, radians)."""


def _is_angle(key: str) -> bool:
    return key.endswith("_rad") or key in ANGLE_KEYS


def _round(value: Any, decimals: int) -> Any:
    if isinstance(value, float):
        return round(value, decimals) if math.isfinite(value) else None
    if isinstance(value, dict):
        return {key: _member(key, item) for key, item in value.items()}
    if isinstance(value, list | tuple):
        return [_round(item, decimals) for item in value]
    return value


def _member(key: Any, value: Any) -> Any:
    """``value`` under name ``key``, rounded as that name says."""
    name = key if isinstance(key, str) else ""
    if name in POSE_KEYS and isinstance(value, list | tuple) and len(value) == 3:
        return [_round(value[0], DECIMALS), _round(value[1], DECIMALS), _round(value[2], DECIMALS_RAD)]
    return _round(value, DECIMALS_RAD if _is_angle(name) else DECIMALS)


def rounded(document: Any, *, key: str = "") -> Any:
    """``document`` (dicts, lists, tuples, numbers, strings, None) with every float rounded by its name (see the
    module docstring) and non-finite floats as None; tuples become lists. ``key`` names the document itself."""
    return _member(key, document)


def json_bytes(document: Any, *, indent: int | None = None) -> bytes:
    """``document`` :func:`rounded` as compact UTF-8 JSON (or indented by ``indent``)."""
    separators = (",", ":") if indent is None else (",", ": ")
    return json.dumps(rounded(document), ensure_ascii=False, allow_nan=False, indent=indent,
                      separators=separators).encode()
