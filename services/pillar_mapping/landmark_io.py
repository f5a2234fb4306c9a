"""Landmark tables on disk: CSV ``x,y,sxx,sxy,syy`` in metres and m^2."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import numpy.typing as npt

from services.pillar_mapping.errors import PillarMappingError

FloatArray = npt.NDArray[np.float64]

HEADER = "x,y,sxx,sxy,syy"


def write_landmarks_csv(path: Path, means: FloatArray, covs: FloatArray) -> None:
    """Write (N, 2) positions and (N, 2, 2) covariances as ``x,y,sxx,sxy,syy`` rows."""
    table = np.column_stack([means, covs[:, 0, 0], covs[:, 0, 1], covs[:, 1, 1]]) if len(means) else np.zeros((0, 5))
    np.savetxt(path, table, delimiter=",", header=HEADER, comments="", fmt="%.6g")


def read_landmarks_csv(path: Path) -> FloatArray:
    """The (N, 5) table of a landmark CSV (header line required; empty files give (0, 5))."""
    try:
        lines = Path(path).read_text().splitlines()
    except OSError as err:
        raise PillarMappingError(f"cannot read landmarks {path}: {err}") from err
    if not lines or [c.strip() for c in lines[0].split(",")] != HEADER.split(","):
        raise PillarMappingError(f"{path}: first line must be the header {HEADER!r}")
    rows = []
    for number, line in enumerate(lines[1:], start=2):
        if not line.strip():
            continue
        cells = line.split(",")
        if len(cells) != 5:
            raise PillarMappingError(f"{path}:{number}: expected 5 values, got {len(cells)}")
        try:
            rows.append([float(c) for c in cells])
        except ValueError as err:
            raise PillarMappingError(f"{path}:{number}: {err}") from err
    return np.asarray(rows, dtype=np.float64).reshape(-1, 5)
