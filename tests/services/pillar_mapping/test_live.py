"""What the live worker fits while a survey goes on: partial landmark maps, and the site's rack profiles."""

import numpy as np
import pytest
from pydantic import ValidationError
from scipy.spatial import cKDTree

from services.pillar_mapping import BearingOnlyMapper, LandmarkMap, PillarMappingError, fit_landmark_map
from services.pillar_mapping.evaluation import drive_aisles, simulated_bearings
from services.pillar_mapping.synthetic import rack_region
from shared.settings import Settings


@pytest.mark.parametrize("seed", [3])
def test_fits_of_a_partly_surveyed_hall_make_no_bin_outside_the_racks(seed: int) -> None:
    rng = np.random.default_rng(seed)
    hall = rack_region(aisles=3, bays=10, cross_aisle_every=5, cross_aisle_width_m=3.0)
    mapper = BearingOnlyMapper()
    sigma = np.deg2rad(0.1)
    poses = drive_aisles(hall, 0.5)
    published = []
    for k, pose in enumerate(poses, start=1):
        bearings = simulated_bearings(hall.uprights, pose, rng, sigma_rad=sigma, clutter_rate=0.2, miss_rate=0.2)
        mapper.observe(pose, bearings, np.full(bearings.size, sigma))
        if k % 10 == 0 or k == len(poses):
            published.append(np.array([b.centre for b in fit_landmark_map(mapper.reliable_landmarks()).bins]))

    truth = cKDTree(hall.bin_centres)
    for k, centres in enumerate(published):
        if len(centres):
            off, _ = truth.query(centres)
            assert np.all(off <= 0.1), f"fit {k}: bins {centres[off > 0.1].round(2).tolist()} are in no rack"
    found, _ = cKDTree(published[-1]).query(hall.bin_centres)
    assert np.all(found <= 0.1)


def test_imprecise_landmarks_wait_for_more_views() -> None:
    hall = rack_region(aisles=1, bays=6)
    means = hall.uprights.copy()
    precise = np.tile(np.eye(2) * 0.01**2, (len(means), 1, 1))
    vague = np.tile(np.diag([0.2**2, 0.01**2]), (len(means), 1, 1))
    counts = np.full(len(means), 10, dtype=np.int64)

    assert fit_landmark_map(LandmarkMap(means, precise, counts)).bins
    assert fit_landmark_map(LandmarkMap(means, vague, counts)).bins == []
    with pytest.raises(PillarMappingError, match="max_sigma_m"):
        fit_landmark_map(LandmarkMap(means, precise, counts), max_sigma_m=0.0)


def test_a_site_sets_its_rack_profiles_in_the_environment(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv(
        "AISLE_PILLARS__RACK_PROFILES",
        '[{"levels_m": [0, 1.6, 3.2], "area": [[0, 0], [50, 0], [50, 30]]}, {"levels_m": [0, 1.5]}]',
    )
    profiles = Settings().pillars.rack_profiles
    assert [p.levels_m for p in profiles] == [[0.0, 1.6, 3.2], [0.0, 1.5]]
    assert profiles[1].area is None

    monkeypatch.setenv("AISLE_PILLARS__RACK_PROFILES", '[{"levels_m": [0, 1.6, 1.2]}]')
    with pytest.raises(ValidationError, match="increasing"):
        Settings()
