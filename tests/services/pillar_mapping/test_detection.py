import numpy as np
import pytest
from scipy.ndimage import gaussian_filter1d

from services.pillar_mapping import PillarMappingError, detect_pillars
from services.pillar_mapping.evaluation import detection_scores
from services.pillar_mapping.synthetic import default_camera, rack_region, rack_scene, render_fisheye
from services.pillar_mapping.wavelet import dog_peaks


def test_dog_peaks_finds_the_centre_of_a_pair_of_opposite_edges() -> None:
    box = np.zeros(720)
    box[300:321] = 5.0
    signal = np.gradient(gaussian_filter1d(box, 2.0))
    signal += np.random.default_rng(0).normal(0, 0.01, signal.size)
    peaks = dog_peaks(signal, np.geomspace(1, 40, 12), min_snr=6)
    assert peaks.positions.size == 1
    assert abs(peaks.positions[0] - 310) < 0.5
    assert 5 <= peaks.scales[0] <= 20


@pytest.mark.slow
def test_detect_pillars_finds_uprights_in_rendered_fisheye_frames() -> None:
    rng = np.random.default_rng(7)
    layout = rack_region(aisles=2, bays=8)
    scene = rack_scene(layout, rng)
    score = detection_scores(default_camera(size_px=480), scene, layout, rng, 6)
    assert score.true_positives > 50
    assert score.recall >= 0.95
    assert score.precision >= 0.95
    assert np.rad2deg(np.median(score.errors_rad)) < 1.0


def test_detect_pillars_bearing_points_at_a_single_upright() -> None:
    rng = np.random.default_rng(1)
    camera = default_camera(size_px=480)
    layout = rack_region(aisles=1, bays=1)
    scene = rack_scene(layout, rng, pallet_fraction=0.0, beam_levels_m=())
    scene = scene._replace(uprights=np.array([[3.0, 1.0]]))
    image, _ = render_fisheye(camera, scene, (0.0, 0.0, 0.0), rng)
    found = detect_pillars(image, camera)
    # default mount: optical (x, y) = vehicle (-y, -x)
    assert found.bearings_rad.size == 1
    assert abs(found.bearings_rad[0] - np.arctan2(-3.0, -1.0)) < np.deg2rad(0.3)
    assert found.sigmas_rad[0] > 0


def test_detect_pillars_sees_nothing_in_an_empty_hall() -> None:
    rng = np.random.default_rng(2)
    camera = default_camera(size_px=320)
    scene = rack_scene(rack_region(aisles=1, bays=1), rng)._replace(uprights=np.zeros((0, 2)), boxes=())
    image, _ = render_fisheye(camera, scene, (0.0, 0.0, 0.0), rng)
    assert detect_pillars(image, camera).bearings_rad.size == 0


def test_detect_pillars_rejects_an_image_of_the_wrong_size() -> None:
    with pytest.raises(PillarMappingError, match="calibration is for"):
        detect_pillars(np.zeros((100, 120, 3), np.uint8), default_camera(size_px=320))
