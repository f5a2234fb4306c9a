"""Map sharpness and wall agreement with a reference map."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from services.occupancy_mapping import OccupancyMappingError, sharpness, wall_agreement
from shared.store.records import GridLayer


def _rooms(seed: int = 5) -> np.ndarray:
    """A 12 x 10 m floor at 0.05 m: free inside, one-cell walls, a few random partitions."""
    rng = np.random.default_rng(seed)
    occ = np.full((200, 240), -1, np.int8)
    occ[10:190, 10:230] = 0
    occ[10, 10:230] = occ[189, 10:230] = 100
    occ[10:190, 10] = occ[10:190, 229] = 100
    for _ in range(4):
        c = int(rng.integers(40, 200))
        occ[10 : int(rng.integers(80, 170)), c] = 100
        r = int(rng.integers(40, 160))
        occ[r, int(rng.integers(10, 100)) : int(rng.integers(120, 229))] = 100
    return occ


def _blur(occ: np.ndarray, sigma_cells: float) -> np.ndarray:
    """Walls spread by a Gaussian of ``sigma_cells``, peak kept at 100: what pose noise does to a map."""
    walls = cv2.GaussianBlur((occ == 100).astype(np.float32), (0, 0), sigma_cells)
    walls /= walls.max()
    out: np.ndarray = np.rint(100.0 * walls).astype(np.int8)
    out[occ < 0] = -1
    return out


def test_sharpness_is_high_for_thin_walls_and_drops_when_blurred() -> None:
    occ = _rooms()
    crisp = sharpness(occ)
    assert crisp > 0.95
    previous = crisp
    for sigma in (0.8, 1.5, 2.5):
        value = sharpness(_blur(occ, sigma))
        assert value < previous
        previous = value


def test_sharpness_drops_when_map_is_smeared() -> None:
    occ = _rooms()
    smeared = np.maximum(occ, np.roll(occ, 1, axis=1))
    smeared = np.maximum(smeared, np.roll(occ, 2, axis=1))
    assert sharpness(smeared) < sharpness(occ) - 0.1


def test_sharpness_of_wall_free_map_is_zero() -> None:
    assert sharpness(np.zeros((5, 5), np.int8)) == 0.0


def test_wall_agreement_recovers_a_rigid_transform() -> None:
    reference = GridLayer("ref", _rooms(), 0.05, -2.0, 1.0)
    yaw, tx, ty = 0.4, 3.0, -1.5
    # ours = reference moved by an unknown transform, drawn at 0.05 m
    rows, cols = np.nonzero(reference.data == 100)
    x = reference.origin_x_m + (cols + 0.5) * 0.05
    y = reference.origin_y_m + (rows + 0.5) * 0.05
    c, s = math.cos(yaw), math.sin(yaw)
    xo, yo = c * x - s * y + tx, s * x + c * y + ty
    ours = np.zeros((600, 600), np.int8)
    ours[((yo + 10.0) / 0.05).astype(int), ((xo + 10.0) / 0.05).astype(int)] = 100
    result = wall_agreement(GridLayer("ours", ours, 0.05, -10.0, -10.0), reference, tolerance_m=0.1)
    assert result.fraction > 0.95
    assert result.fraction_in_view > 0.95
    assert result.ours_to_reference.yaw_rad == pytest.approx(-yaw, abs=math.radians(0.5))
    # the reference wall corner maps back onto itself
    px, py = xo[0], yo[0]
    t = result.ours_to_reference
    back = (
        math.cos(t.yaw_rad) * px - math.sin(t.yaw_rad) * py + t.x_m,
        math.sin(t.yaw_rad) * px + math.cos(t.yaw_rad) * py + t.y_m,
    )
    assert back == pytest.approx((x[0], y[0]), abs=0.1)


def test_wall_agreement_is_low_for_an_unrelated_map() -> None:
    reference = GridLayer("ref", _rooms(5), 0.05, 0.0, 0.0)
    other = np.full((200, 240), 0, np.int8)
    other[100, 20:60] = 100
    assert wall_agreement(GridLayer("ours", other, 0.05, 0.0, 0.0), reference).fraction < 0.1


def test_wall_agreement_needs_walls() -> None:
    empty = GridLayer("ours", np.zeros((4, 4), np.int8), 0.05, 0.0, 0.0)
    with pytest.raises(OccupancyMappingError, match="occupied cells"):
        wall_agreement(empty, GridLayer("ref", _rooms(), 0.05, 0.0, 0.0))
