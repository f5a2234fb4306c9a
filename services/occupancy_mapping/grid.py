"""A log-odds occupancy grid that grows as the robot explores."""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from services.occupancy_mapping.errors import OccupancyMappingError
from services.occupancy_mapping.raycast import RayCasting, free_space_mask
from shared.store.records import GridLayer
from shared.transforms import Pose2D

_PROB_EPS = 1e-3


class OccupancyGrid:
    """Log-odds occupancy grid in a fixed frame, ``data[row, col]`` with row 0 at the lowest y.

    The grid starts as one chunk centred on the frame origin and pads itself by whole chunks
    whenever a scan reaches beyond it; padding moves the origin by whole cells, so a cell keeps
    its world position and value.

    Parameters
    ----------
    resolution_m : float
        Cell edge length in metres.
    chunk_m : float
        Growth step in metres (rounded up to whole cells).
    hit_logodds, miss_logodds : float
        Log-odds added to a cell a beam ends in, and to a cell a beam passes through.
    min_logodds, max_logodds : float
        Clamp, so that a cell can change its mind after a few observations.
    ray_casting : RayCasting
        Free-space rasterisation method.
    """

    def __init__(
        self,
        *,
        resolution_m: float,
        chunk_m: float = 8.0,
        hit_logodds: float = 0.85,
        miss_logodds: float = -0.4,
        min_logodds: float = -2.0,
        max_logodds: float = 3.5,
        ray_casting: RayCasting = RayCasting.POLYGON,
    ) -> None:
        if not (math.isfinite(resolution_m) and resolution_m > 0):
            raise OccupancyMappingError(f"resolution_m must be positive, got {resolution_m}")
        if not (math.isfinite(chunk_m) and chunk_m > 0):
            raise OccupancyMappingError(f"chunk_m must be positive, got {chunk_m}")
        if not (min_logodds < 0 < max_logodds and miss_logodds < 0 < hit_logodds):
            raise OccupancyMappingError(
                "need min_logodds < 0 < max_logodds and miss_logodds < 0 < hit_logodds, got "
                f"{min_logodds}, {max_logodds}, {miss_logodds}, {hit_logodds}"
            )
        self._resolution = float(resolution_m)
        self._chunk = max(1, math.ceil(chunk_m / resolution_m))
        self._hit, self._miss = float(hit_logodds), float(miss_logodds)
        self._min, self._max = float(min_logodds), float(max_logodds)
        self._ray_casting = ray_casting
        self._logodds = np.zeros((self._chunk, self._chunk), dtype=np.float32)
        self._observed = np.zeros((self._chunk, self._chunk), dtype=bool)
        self._origin_col = -(self._chunk // 2)  # world cell index of column 0
        self._origin_row = -(self._chunk // 2)

    @property
    def resolution_m(self) -> float:
        """Cell edge length in metres."""
        return self._resolution

    @property
    def origin_x_m(self) -> float:
        """x of the lower-left corner of cell (0, 0), metres."""
        return self._origin_col * self._resolution

    @property
    def origin_y_m(self) -> float:
        """y of the lower-left corner of cell (0, 0), metres."""
        return self._origin_row * self._resolution

    @property
    def shape(self) -> tuple[int, int]:
        """(rows, cols)."""
        return (int(self._logodds.shape[0]), int(self._logodds.shape[1]))

    @property
    def logodds(self) -> npt.NDArray[np.float32]:
        """A copy of the log-odds, (rows, cols) float32; 0 where never observed."""
        return self._logodds.copy()

    def _grow(self, min_cr: npt.NDArray[np.int64], max_cr: npt.NDArray[np.int64]) -> None:
        """Pad by whole chunks so world cells ``min_cr..max_cr`` (inclusive, (col, row)) fit."""
        rows, cols = self.shape
        lo_c, lo_r = int(min_cr[0]) - self._origin_col, int(min_cr[1]) - self._origin_row
        hi_c, hi_r = int(max_cr[0]) - self._origin_col, int(max_cr[1]) - self._origin_row
        k = self._chunk
        left = -(lo_c // k) * k if lo_c < 0 else 0
        bottom = -(lo_r // k) * k if lo_r < 0 else 0
        right = -((cols - 1 - hi_c) // k) * k if hi_c >= cols else 0
        top = -((rows - 1 - hi_r) // k) * k if hi_r >= rows else 0
        if left or bottom or right or top:
            pad = ((bottom, top), (left, right))
            self._logodds = np.pad(self._logodds, pad)
            self._observed = np.pad(self._observed, pad)
            self._origin_col -= left
            self._origin_row -= bottom

    def integrate(
        self,
        pose: Pose2D,
        ranges: npt.ArrayLike,
        angles: npt.ArrayLike,
        *,
        range_min_m: float,
        range_max_m: float,
        max_range_m: float,
        no_return_clear_m: float = 5.0,
    ) -> int:
        """Add one scan taken from ``pose``; return how many beams were used.

        Parameters
        ----------
        pose : Pose2D
            Sensor pose in the grid's frame (metres, radians).
        ranges : (n,) array_like
            Ranges in metres. A return with ``range_min_m <= r < min(range_max_m, max_range_m)``
            marks its end cell occupied and the cells before it free; longer returns and ``+inf``
            (no return) never mark anything occupied and only clear free space up to
            ``no_return_clear_m``; NaN, negative, ``-inf`` and too-short returns are skipped
            (``n`` minus the result).
        angles : (n,) array_like
            Beam bearings in the sensor frame, radians.
        range_min_m, range_max_m : float
            The sensor's valid interval, as in sensor_msgs/LaserScan.
        max_range_m : float
            Returns at or beyond this are not trusted as obstacles.
        no_return_clear_m : float
            How far a beam without a usable return clears free space, metres (capped by the
            range limits). Dropouts on dark or shiny surfaces also read as "no return", so a
            short cap keeps them from erasing walls; 0 disables clearing by such beams.

        Returns
        -------
        int
            Number of beams that updated the grid.
        """
        r = np.asarray(ranges, dtype=np.float64).ravel()
        a = np.asarray(angles, dtype=np.float64).ravel()
        if r.size != a.size:
            raise OccupancyMappingError(f"{r.size} ranges but {a.size} angles")
        if not all(math.isfinite(v) for v in pose):
            raise OccupancyMappingError(f"pose must be finite, got {pose}")
        if not np.all(np.isfinite(a)):
            raise OccupancyMappingError("beam angles must be finite")
        if not (
            0.0 <= range_min_m < range_max_m
            and max_range_m > 0
            and math.isfinite(max_range_m)
            and no_return_clear_m >= 0.0
        ):
            raise OccupancyMappingError(
                "need 0 <= range_min_m < range_max_m, finite max_range_m > 0 and no_return_clear_m >= 0, "
                f"got "
                f"{range_min_m}, {range_max_m}, {max_range_m}, {no_return_clear_m}"
            )
        limit = min(range_max_m, max_range_m)
        with np.errstate(invalid="ignore"):
            valid = (r >= range_min_m) & (r >= 0.0)  # False for NaN and -inf
            hit = valid & (r < limit)
        no_return = valid & ~hit
        if no_return_clear_m == 0.0:
            no_return[:] = False
        usable = hit | no_return
        n_used = int(np.count_nonzero(usable))
        if n_used == 0:
            return 0
        free_len = np.where(hit, np.maximum(r - self._resolution, 0.0), min(limit, no_return_clear_m))
        free_len = np.where(usable, free_len, 0.0)
        bearing = a + pose.yaw_rad
        cos_b, sin_b = np.cos(bearing), np.sin(bearing)
        inv = 1.0 / self._resolution
        ox, oy = pose.x_m * inv - 0.5, pose.y_m * inv - 0.5  # world cell coords, centres at integers
        free_cr = np.stack([ox + free_len * cos_b * inv, oy + free_len * sin_b * inv], axis=1)
        hit_r = np.where(hit, r, 0.0)
        hit_cr = np.rint(np.stack([ox + hit_r * cos_b * inv, oy + hit_r * sin_b * inv], axis=1)[hit]).astype(
            np.int64
        )
        origin = np.array([ox, oy])
        pts = np.vstack([free_cr[usable], origin[None, :]])
        lo = np.floor(pts.min(axis=0)).astype(np.int64)
        hi = np.ceil(pts.max(axis=0)).astype(np.int64)
        if hit_cr.size:
            lo = np.minimum(lo, hit_cr.min(axis=0))
            hi = np.maximum(hi, hit_cr.max(axis=0))
        self._grow(lo, hi)
        c0, r0 = int(lo[0]) - self._origin_col, int(lo[1]) - self._origin_row
        c1, r1 = int(hi[0]) - self._origin_col + 1, int(hi[1]) - self._origin_row + 1
        shift = np.array([lo[0], lo[1]], dtype=np.float64)
        free = free_space_mask(
            origin - shift, free_cr - shift, hit, no_return, (r1 - r0, c1 - c0), method=self._ray_casting
        )
        hits = np.zeros_like(free)
        hits[hit_cr[:, 1] - lo[1], hit_cr[:, 0] - lo[0]] = True
        free &= ~hits
        patch = self._logodds[r0:r1, c0:c1]
        patch[free] += self._miss
        patch[hits] += self._hit
        np.clip(patch, self._min, self._max, out=patch)
        self._observed[r0:r1, c0:c1] |= free | hits
        return n_used

    def occupancy(self) -> npt.NDArray[np.int8]:
        """Occupancy in ROS convention, (rows, cols) int8: -1 unknown, else probability in percent."""
        prob = 1.0 / (1.0 + np.exp(-self._logodds.astype(np.float64)))
        out = np.rint(prob * 100.0).astype(np.int8)
        out[~self._observed] = -1
        return out

    def to_layer(self, name: str) -> GridLayer:
        """The occupancy as a store layer."""
        return GridLayer(
            name=name,
            data=self.occupancy(),
            resolution_m=self._resolution,
            origin_x_m=self.origin_x_m,
            origin_y_m=self.origin_y_m,
        )

    @classmethod
    def from_occupancy(
        cls,
        data: npt.ArrayLike,
        *,
        resolution_m: float,
        origin_x_m: float,
        origin_y_m: float,
        chunk_m: float = 8.0,
        ray_casting: RayCasting = RayCasting.POLYGON,
    ) -> OccupancyGrid:
        """Resume from a stored occupancy layer (int8, -1 unknown, 0..100).

        The origin must lie on the grid's cell lattice (a whole number of cells from 0), which
        every grid this class writes satisfies.
        """
        occ = np.asarray(data)
        if occ.ndim != 2 or 0 in occ.shape:
            raise OccupancyMappingError(f"occupancy must be a non-empty 2-D array, got shape {occ.shape}")
        if not np.issubdtype(occ.dtype, np.integer) or occ.min() < -1 or occ.max() > 100:
            raise OccupancyMappingError("occupancy must be integers in -1..100")
        grid = cls(resolution_m=resolution_m, chunk_m=chunk_m, ray_casting=ray_casting)
        cols = origin_x_m / resolution_m
        rows = origin_y_m / resolution_m
        if abs(cols - round(cols)) > 1e-3 or abs(rows - round(rows)) > 1e-3:
            raise OccupancyMappingError(
                f"origin ({origin_x_m}, {origin_y_m}) m is not a whole number of {resolution_m} m cells"
            )
        observed = occ >= 0
        prob = np.clip(occ.astype(np.float64) / 100.0, _PROB_EPS, 1.0 - _PROB_EPS)
        logodds = np.clip(np.log(prob / (1.0 - prob)), grid._min, grid._max)
        grid._logodds = np.where(observed, logodds, 0.0).astype(np.float32)
        grid._observed = observed
        grid._origin_col, grid._origin_row = round(cols), round(rows)
        return grid
