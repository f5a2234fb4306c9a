import numpy as np

from services.load_scenes import LikelihoodSettings, prepare_rays, scene_log_likelihood
from services.load_scenes.boxes import to_map_frame
from services.load_scenes.likelihood import entry_distances
from services.load_scenes.model import Bay, DepthEvidence

BAY = Bay(key="R1/001", row="R1", aisle=1, bay=1, origin=(10.0, 5.0), yaw_rad=0.7, width_m=2.7, depth_m=1.2,
          levels_z_m=(0.0, 1.6), bin_ids=("b0", "b1"))


def _view(points_uvz: np.ndarray, origin_uvz: tuple[float, float, float]) -> DepthEvidence:
    o = to_map_frame(BAY, np.array([origin_uvz]))[0]
    return DepthEvidence(origin=(float(o[0]), float(o[1]), float(o[2])), points=to_map_frame(BAY, points_uvz),
                         stamp_ns=1)


def test_entry_distance_of_a_ray_into_a_turned_box() -> None:
    view = _view(np.array([[0.0, 0.5, 0.5]]), (0.0, -2.0, 0.5))
    rays = prepare_rays(BAY, [view], LikelihoodSettings())
    t = entry_distances(rays, np.array([[0.0, 0.6, 0.5], [2.0, 0.6, 0.5]]), np.array([[1.0, 1.0, 1.0]] * 2),
                        np.array([0.0, 0.3]))
    assert abs(t[0, 0] - 2.1) < 1e-9 and np.isinf(t[0, 1])


def test_points_on_a_box_face_favour_it_and_rays_through_it_reject_it() -> None:
    u = np.linspace(-0.3, 0.3, 7)
    face = np.column_stack([u, np.full(7, 0.1), np.full(7, 0.5)])  # on the front face of the box below
    wall = np.column_stack([u, np.full(7, 1.5), np.full(7, 0.5)])  # behind the bay: the box is not there
    box_c, box_s = np.array([[0.0, 0.6, 0.5]]), np.array([[0.8, 1.0, 0.8]])
    s = LikelihoodSettings()
    for points, box_better in ((face, True), (wall, False)):
        rays = prepare_rays(BAY, [_view(points, (0.0, -2.0, 0.5))], s)
        table = entry_distances(rays, box_c, box_s, np.zeros(1))
        with_box = scene_log_likelihood(rays, table, np.array([True]), s)
        without = scene_log_likelihood(rays, table, np.array([False]), s)
        assert (with_box > without) == box_better


def test_points_that_are_not_finite_are_dropped() -> None:
    pts = np.array([[0.0, 0.5, 0.5], [np.nan, 0.5, 0.5]])
    rays = prepare_rays(BAY, [_view(pts, (0.0, -2.0, 0.5))], LikelihoodSettings())
    assert rays.range_m.shape == (1,)
