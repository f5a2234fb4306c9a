"""Object retrieval: match segment dimensions against a prior database of object sizes.

Each segment's (width, height) is compared with every database entry of typical dimensions per
class using a Mahalanobis distance whose diagonal covariance grows with range (depth noise), at
the image borders (a cut-off object looks smaller: Gaussian border weights from a lookup table)
and by constant occlusion terms, larger for width than for height. A KD-tree over the database
finds the candidates: every entry within the Mahalanobis gate lies within
``gate * max(sigma_w, sigma_h)`` in plain metres, so a ball query followed by the exact
Mahalanobis distance is exact.
"""

from __future__ import annotations

import csv
from dataclasses import dataclass
from pathlib import Path
from typing import NamedTuple

import numpy as np
import numpy.typing as npt
from scipy.spatial import cKDTree

from services.object_labelling.camera import CameraIntrinsics
from services.object_labelling.errors import ObjectLabellingError
from services.object_labelling.segments import Segment

DEFAULT_PRIORS = Path(__file__).with_name("data") / "object_priors.csv"


class Proposal(NamedTuple):
    """A segment with its closest class by dimensions (``None`` when nothing is within the gate).

    ``distances`` holds the smallest Mahalanobis distance per class that passed the gate;
    ``box`` is the ROI (row_min, col_min, row_max, col_max), inclusive pixels.
    """

    segment: Segment
    label: str | None
    distance: float
    distances: dict[str, float]
    box: tuple[int, int, int, int]


def border_weights(size_px: int, *, sigma_px: float) -> npt.NDArray[np.float64]:
    """Lookup table: weight in [0, 1] of an object edge ``d`` pixels from the image border, exp(-d^2 / 2 sigma^2)."""
    if size_px < 1 or sigma_px <= 0:
        raise ObjectLabellingError(f"need size_px >= 1 and sigma_px > 0, got {size_px}, {sigma_px}")
    d = np.arange(size_px, dtype=np.float64)
    return np.asarray(np.exp(-0.5 * (d / sigma_px) ** 2))


@dataclass(frozen=True)
class PriorDatabase:
    """Typical (width, height) in metres per class, with a KD-tree over them."""

    classes: tuple[str, ...]
    dimensions: npt.NDArray[np.float64]  # (n, 2) width_m, height_m
    tree: cKDTree

    @classmethod
    def from_rows(cls, rows: list[tuple[str, float, float]]) -> PriorDatabase:
        """Build from (class, width_m, height_m) rows."""
        if not rows:
            raise ObjectLabellingError("prior database is empty")
        dims = np.array([[w, h] for _, w, h in rows], dtype=np.float64)
        if not (np.isfinite(dims).all() and (dims > 0).all()):
            raise ObjectLabellingError("prior dimensions must be positive and finite")
        return cls(tuple(c for c, _, _ in rows), dims, cKDTree(dims))

    @classmethod
    def read_csv(cls, path: Path = DEFAULT_PRIORS) -> PriorDatabase:
        """Read a ``class,view,width_m,height_m`` CSV (the default ships in ``data/``)."""
        try:
            with path.open(newline="") as stream:
                return cls.from_rows(
                    [(r["class"], float(r["width_m"]), float(r["height_m"])) for r in csv.DictReader(stream)]
                )
        except (OSError, KeyError, ValueError) as err:
            raise ObjectLabellingError(f"cannot read prior database {path}: {err}") from err


def retrieve(
    found: list[Segment],
    database: PriorDatabase,
    intrinsics: CameraIntrinsics,
    *,
    occlusion_width_m: float = 0.25,
    occlusion_height_m: float = 0.05,
    range_sigma_per_m: float = 0.01,
    border_sigma_px: float = 31.05,
    border_extent_m: float = 3.0,
    max_distance: float = 3.0,
) -> list[Proposal]:
    """Class proposals and ROIs for segments by Mahalanobis nearest neighbour in the prior database.

    Parameters
    ----------
    found
        Segments of one frame.
    database
        Prior object dimensions.
    intrinsics
        The camera model (image size for the border weights).
    occlusion_width_m, occlusion_height_m
        Constant standard deviations for occlusions, which shorten widths more than heights.
    range_sigma_per_m
        Standard deviation per metre of range from depth noise, for both dimensions.
    border_sigma_px, border_extent_m
        A segment whose box touches the left/right border (width) or the top border (height) gets
        up to ``border_extent_m`` more standard deviation, weighted by the Gaussian border table.
    max_distance
        Mahalanobis gate; nothing within it means no label.

    Returns
    -------
    list of Proposal
        One per segment, same order.
    """
    lut = border_weights(max(intrinsics.width, intrinsics.height), sigma_px=border_sigma_px)
    proposals = []
    for segment in found:
        row_min, col_min, row_max, col_max = segment.box
        side = int(np.clip(min(col_min, intrinsics.width - 1 - col_max), 0, lut.size - 1))
        top = int(np.clip(row_min, 0, lut.size - 1))
        ranged = range_sigma_per_m * segment.range_m
        sigma = np.array(
            [
                occlusion_width_m + ranged + border_extent_m * lut[side],
                occlusion_height_m + ranged + border_extent_m * lut[top],
            ]
        )
        query = np.array([segment.width_m, segment.height_m])
        candidates = database.tree.query_ball_point(query, max_distance * sigma.max())
        distances: dict[str, float] = {}
        for index in candidates:
            d = float(np.sqrt((((query - database.dimensions[index]) / sigma) ** 2).sum()))
            name = database.classes[index]
            if d <= max_distance and d < distances.get(name, np.inf):
                distances[name] = d
        label = min(distances, key=distances.__getitem__) if distances else None
        box = (
            max(row_min, 0),
            max(col_min, 0),
            min(row_max, intrinsics.height - 1),
            min(col_max, intrinsics.width - 1),
        )
        proposals.append(Proposal(segment, label, distances[label] if label else float("inf"), distances, box))
    return proposals
