"""The fitted rack layout as GeoJSON and as map-store features; ``aisle racks fit`` end to end."""

from __future__ import annotations

import json
import logging
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, NamedTuple

import numpy as np
import numpy.typing as npt

from services.pillar_mapping.bins import StorageBin, storage_bins
from services.pillar_mapping.errors import PillarMappingError
from services.pillar_mapping.landmark_io import read_landmarks_csv
from services.pillar_mapping.levels import RackProfile, bins_on_levels
from services.pillar_mapping.rows import RackRow, fit_rack_rows
from shared.bins import AccessPose, Bin
from shared.store import Feature

if TYPE_CHECKING:
    from services.pillar_mapping.mapper import LandmarkMap  # importing it imports GTSAM

logger = logging.getLogger(__name__)

FloatArray = npt.NDArray[np.float64]


class RackLayout(NamedTuple):
    """Rows, bins, and the input landmarks no row explains (``outliers`` (K, 2) metres)."""

    rows: list[RackRow]
    bins: list[StorageBin]
    outliers: FloatArray


def _point(xy: FloatArray) -> dict[str, Any]:
    return {"type": "Point", "coordinates": [float(xy[0]), float(xy[1])]}


def aisle_key(aisle: int) -> str:
    """Key of an aisle's ``corridor`` feature, e.g. ``aisle-03``."""
    return f"aisle-{aisle:02d}"


def aisle_corridors(bins: list[StorageBin]) -> list[Feature]:
    """One ``corridor`` feature per aisle: the rectangle between the bin openings that face it.

    Across the aisle it spans from the front edges of the bins on one side to those on the other; an
    aisle with racks on one side only is mirrored about the access poses, which lie on its centre line.
    Along it, it spans the bins' openings. Properties: ``label`` corridor, ``aisle``, ``width_m``,
    ``length_m``, ``bins``.
    """
    out = []
    for aisle in sorted({b.aisle for b in bins}):
        members = [b for b in bins if b.aisle == aisle]
        yaw = members[0].access_pose[2]
        v = np.array([np.cos(yaw), np.sin(yaw)])  # across the aisle, towards the first bin
        u = np.array([-v[1], v[0]])  # along the aisle
        fronts = np.vstack([b.footprint[:2] for b in members])
        access = np.array([b.access_pose[:2] for b in members])
        centre_v = float(np.median(access @ v))
        mirrored = 2.0 * centre_v - fronts @ v
        across = np.concatenate([fronts @ v, mirrored])
        along = fronts @ u
        lo_v, hi_v, lo_u, hi_u = across.min(), across.max(), along.min(), along.max()
        corners = [lo_u * u + lo_v * v, hi_u * u + lo_v * v, hi_u * u + hi_v * v, lo_u * u + hi_v * v]
        ring = [[round(float(c[0]), 4), round(float(c[1]), 4)] for c in corners]
        out.append(Feature("corridor", aisle_key(aisle), {"type": "Polygon", "coordinates": [[*ring, ring[0]]]}, {
            "kind": "corridor",
            "label": "corridor",
            "aisle": aisle,
            "width_m": round(float(hi_v - lo_v), 3),
            "length_m": round(float(hi_u - lo_u), 3),
            "bins": len(members),
        }))
    return out


def layout_features(layout: RackLayout) -> dict[str, list[Feature]]:
    """Map-store features of a layout, by kind (``pillar``, ``rack_row``, ``bin``, and ``corridor`` for the
    aisles, :func:`aisle_corridors`), for one RevisionWrite.

    Keys are stable across rebuilds where the layout is: bins by id, rows by region and
    position in it, pillars by row and index (outliers by rounded position).
    """
    pillars: list[Feature] = []
    rows: list[Feature] = []
    rank: dict[int, int] = {}
    for row in layout.rows:
        k = rank[row.region] = rank.get(row.region, 0) + 1
        key = f"r{row.region}-{k:03d}"
        rows.append(
            Feature(
                "rack_row",
                key,
                {"type": "LineString", "coordinates": row.uprights.tolist()},
                {
                    "kind": "rack_row",
                    "n": row.n,
                    "d": row.d_m,
                    "theta": row.theta_rad,
                    "x": row.x_m,
                    "y": row.y_m,
                    "region": row.region,
                    "source": "pillar_mapping",
                },
                float(row.observed.mean()),
            )
        )
        for j, (xy, seen) in enumerate(zip(row.uprights, row.observed, strict=True)):
            pillars.append(
                Feature("pillar", f"{key}-{j:03d}", _point(xy), {"kind": "pillar", "observed": bool(seen), "row": key})
            )
    for xy in layout.outliers:
        pillars.append(
            Feature(
                "pillar", f"p{xy[0]:.2f}_{xy[1]:.2f}", _point(xy), {"kind": "pillar", "observed": True, "row": None}
            )
        )
    row_keys = [f.key for f in rows]
    bins = [
        Bin(
            id=b.id,
            centre=(float(b.centre[0]), float(b.centre[1])),
            aisle=b.aisle,
            bay=b.bay,
            level=b.level,
            z_m=b.z_m,
            footprint=tuple((float(x), float(y)) for x, y in [*b.footprint.tolist(), b.footprint[0].tolist()]),
            access_pose=AccessPose(*b.access_pose),
            row=row_keys[b.row],
            back_row=row_keys[b.back_row],
            confidence=b.confidence,
        ).feature()
        for b in layout.bins
    ]
    unique = {f.key: f for f in pillars}
    return {"pillar": list(unique.values()), "rack_row": rows, "bin": bins, "corridor": aisle_corridors(layout.bins)}


def layout_geojson(layout: RackLayout) -> dict[str, Any]:
    """A GeoJSON FeatureCollection (map metres) of a layout; ``properties.kind`` tells the feature kind."""
    by_kind = layout_features(layout)
    features = [
        {"type": "Feature", "id": f.key, "geometry": dict(f.geometry), "properties": dict(f.properties)}
        for kind in ("rack_row", "pillar", "bin")
        for f in by_kind[kind]
    ]
    return {"type": "FeatureCollection", "features": features}


def fit_layout(
    landmarks: npt.ArrayLike, *, profiles: Sequence[RackProfile] = (), **row_options: Any
) -> RackLayout:
    """Rows (:func:`~services.pillar_mapping.rows.fit_rack_rows`) and bins of a landmark table (N, 5), the bins
    on the levels of the site's rack ``profiles`` (:func:`~services.pillar_mapping.levels.bins_on_levels`)."""
    table = np.asarray(landmarks, dtype=np.float64)
    rows = fit_rack_rows(table, **row_options)
    claimed = np.zeros(len(table), dtype=bool)
    for row in rows:
        claimed[row.members] = True
    outliers = table[~claimed, :2] if table.ndim == 2 and len(table) else np.zeros((0, 2))
    return RackLayout(rows, bins_on_levels(storage_bins(rows), profiles), outliers)


def fit_landmark_map(
    landmarks: LandmarkMap,
    *,
    max_sigma_m: float = 0.05,
    profiles: Sequence[RackProfile] = (),
    **row_options: Any,
) -> RackLayout:
    """The layout of a live landmark map (as the worker fits it while the survey goes on).

    Landmarks whose largest standard deviation exceeds ``max_sigma_m`` are left out until more
    views pin them down: bins must come out within 10 cm, which a landmark twice as uncertain as
    that cannot give. The rest are fitted with :func:`fit_layout`, whose bins already need a seen
    upright at a corner or on both sides and racks of the region's common depth, so a partly
    surveyed hall gets fewer bins, not bins where there are none.
    """
    if max_sigma_m <= 0:
        raise PillarMappingError(f"max_sigma_m must be positive, got {max_sigma_m}")
    means = np.asarray(landmarks.means, dtype=np.float64).reshape(-1, 2)
    covs = np.asarray(landmarks.covs, dtype=np.float64).reshape(-1, 2, 2)
    sigma = np.sqrt(np.maximum(np.linalg.eigvalsh(covs)[:, 1], 0.0)) if len(covs) else np.zeros(0)
    keep = sigma <= max_sigma_m
    table = np.column_stack([means[keep], covs[keep].reshape(-1, 4)[:, [0, 1, 3]]])
    return fit_layout(table, profiles=profiles, **row_options)


def fit_racks(
    landmarks: Path | npt.ArrayLike,
    out_dir: Path | None = None,
    *,
    profiles: Sequence[RackProfile] = (),
    **row_options: Any,
) -> RackLayout:
    """``aisle racks fit PILLARS.csv --out DIR [--levels 0,1.5,3]``: fit a layout and write ``DIR/racks.geojson``.

    ``landmarks`` is a CSV path (``x,y,sxx,sxy,syy``) or an (N, 5) array.
    """
    table = read_landmarks_csv(Path(landmarks)) if isinstance(landmarks, str | Path) else landmarks
    layout = fit_layout(table, profiles=profiles, **row_options)
    logger.info(
        "fitted %d rows and %d bins; %d landmarks in no row", len(layout.rows), len(layout.bins), len(layout.outliers)
    )
    if out_dir is not None:
        out = Path(out_dir)
        try:
            out.mkdir(parents=True, exist_ok=True)
            (out / "racks.geojson").write_text(json.dumps(layout_geojson(layout)))
        except OSError as err:
            raise PillarMappingError(f"cannot write {out / 'racks.geojson'}: {err}") from err
    return layout
