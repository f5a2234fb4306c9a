"""2-D scan matching: a correlative search on a likelihood field, refined by point-to-point ICP."""

from __future__ import annotations

import math
from typing import NamedTuple

import cv2
import numpy as np
import numpy.typing as npt
from scipy.ndimage import distance_transform_edt
from scipy.spatial import cKDTree

from services.semantic_fusion import se2
from services.semantic_fusion.errors import SemanticFusionError


class ScanMatch(NamedTuple):
    """Result of :func:`match_scans`.

    ``pose`` (3,) float64 maps source points into the target frame (x, y in metres, yaw in radians);
    ``rmse_m`` is the RMS distance of the inlier correspondences and ``inlier_fraction`` the share of
    source points within ``inlier_m`` of a target point. ``ambiguity`` is the best correlative score
    more than ``distinct_m`` away from the winner divided by the winner's: near 1 along a featureless
    wall or among repeating rack bays, where a good fit says little about where the source is.
    """

    pose: npt.NDArray[np.float64]
    rmse_m: float
    inlier_fraction: float
    ambiguity: float


def _coarse_search(source: npt.NDArray[np.float64], target: npt.NDArray[np.float64],
                   initial: npt.NDArray[np.float64], *, radius_m: float, angle_rad: float, step_m: float,
                   angle_step_rad: float, distinct_m: float) -> tuple[npt.NDArray[np.float64], float]:
    """Best pose on a grid of poses around ``initial`` by summed likelihood-field score, and the ambiguity.

    Per heading the source is rasterised into a template and cross-correlated with the target's
    likelihood field (``cv2.matchTemplate``), which scores every translation at once.
    """
    moved0 = se2.transform_points(initial, source)
    reach = float(np.max(np.hypot(*(moved0 - initial[:2]).T))) * angle_rad
    margin = radius_m + reach + 2.0 * step_m
    lo = np.minimum(target.min(axis=0), moved0.min(axis=0)) - margin
    hi = np.maximum(target.max(axis=0), moved0.max(axis=0)) + margin
    shape = tuple(int(v) for v in np.ceil((hi - lo) / step_m) + 1)
    free = np.ones(shape, dtype=bool)
    cells = np.floor((target - lo) / step_m).astype(np.intp)
    free[cells[:, 0], cells[:, 1]] = False
    distance = distance_transform_edt(free)
    field = np.exp(-0.5 * distance**2).astype(np.float32)
    n = round(radius_m / step_m)
    n_angles = round(angle_rad / angle_step_rad)
    windows, corners = [], []
    for dyaw in np.arange(-n_angles, n_angles + 1) * angle_step_rad:
        pose = np.array([initial[0], initial[1], initial[2] + dyaw])
        moved = se2.transform_points(pose, source)
        corner = np.floor((moved.min(axis=0) - lo) / step_m).astype(np.intp)
        local = np.floor((moved - lo) / step_m).astype(np.intp) - corner
        template = np.zeros(tuple(int(v) for v in local.max(axis=0) + 1), dtype=np.float32)
        np.add.at(template, (local[:, 0], local[:, 1]), 1.0)
        scores = cv2.matchTemplate(field, template, cv2.TM_CCORR)
        padded = np.pad(scores, n, constant_values=0.0)
        windows.append(padded[corner[0]: corner[0] + 2 * n + 1, corner[1]: corner[1] + 2 * n + 1])
        corners.append(pose)
    stack = np.stack(windows)
    a, i, j = np.unravel_index(int(np.argmax(stack)), stack.shape)
    best_score = float(stack[a, i, j])
    best = corners[a] + np.array([(i - n) * step_m, (j - n) * step_m, 0.0])
    offsets = (np.arange(2 * n + 1) - n) * step_m
    far = np.hypot(offsets[:, None] - offsets[i], offsets[None, :] - offsets[j]) > distinct_m
    rival = float(np.max(stack[:, far])) if far.any() else 0.0
    return best, (rival / best_score if best_score > 0 else 1.0)


def _rigid_fit(src: npt.NDArray[np.float64], dst: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    """Least-squares rigid transform (x, y, yaw) taking ``src`` onto ``dst`` (Kabsch in 2-D)."""
    mu_s, mu_d = src.mean(axis=0), dst.mean(axis=0)
    a, b = src - mu_s, dst - mu_d
    yaw = math.atan2(float(np.sum(a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0])), float(np.sum(a * b)))
    c, s = math.cos(yaw), math.sin(yaw)
    t = mu_d - np.array([c * mu_s[0] - s * mu_s[1], s * mu_s[0] + c * mu_s[1]])
    return np.array([t[0], t[1], yaw])


def match_scans(
    source_xy: npt.ArrayLike,
    target_xy: npt.ArrayLike,
    *,
    initial_pose: npt.ArrayLike = (0.0, 0.0, 0.0),
    search_radius_m: float = 1.0,
    search_angle_rad: float = 0.1,
    coarse_step_m: float = 0.15,
    coarse_angle_step_rad: float = 0.02,
    distinct_m: float = 0.6,
    max_correspondence_m: float = 0.3,
    inlier_m: float = 0.1,
    max_iterations: int = 30,
) -> ScanMatch:
    """Pose of the ``source`` point set in the ``target``'s frame.

    A brute-force correlative search over translations within ``search_radius_m`` and headings
    within ``search_angle_rad`` of ``initial_pose`` (scoring each candidate on a Gaussian likelihood
    field of the target, ``coarse_step_m`` cells) finds the basin; point-to-point ICP with a
    k-d tree, rejecting pairs further than ``max_correspondence_m``, refines it. The runner-up
    score more than ``distinct_m`` from the winner gives the match's ambiguity.

    Parameters
    ----------
    source_xy, target_xy : (n, 2), (m, 2) array_like
        Points in metres, each in its own frame.
    initial_pose : (3,) array_like
        Prior guess of the source frame in the target frame (x, y metres, yaw radians).

    Raises
    ------
    SemanticFusionError
        Fewer than 3 points on either side, non-finite points, or non-positive search steps.
    """
    source = np.asarray(source_xy, dtype=np.float64).reshape(-1, 2)
    target = np.asarray(target_xy, dtype=np.float64).reshape(-1, 2)
    initial = np.asarray(initial_pose, dtype=np.float64).reshape(3)
    if source.shape[0] < 3 or target.shape[0] < 3:
        raise SemanticFusionError(f"scan matching needs >= 3 points a side, got {source.shape[0]}, {target.shape[0]}")
    if not (np.all(np.isfinite(source)) and np.all(np.isfinite(target)) and np.all(np.isfinite(initial))):
        raise SemanticFusionError("scan matching input must be finite")
    if min(coarse_step_m, coarse_angle_step_rad, max_correspondence_m, inlier_m) <= 0 or max_iterations < 1:
        raise SemanticFusionError("search steps, distances and max_iterations must be positive")
    pose, ambiguity = _coarse_search(source, target, initial, radius_m=max(search_radius_m, 0.0),
                                     angle_rad=max(search_angle_rad, 0.0), step_m=coarse_step_m,
                                     angle_step_rad=coarse_angle_step_rad, distinct_m=distinct_m)
    tree = cKDTree(target)
    for _ in range(max_iterations):
        moved = se2.transform_points(pose, source)
        distance, nearest = tree.query(moved, distance_upper_bound=max_correspondence_m)
        pairs = np.isfinite(distance)
        if pairs.sum() < 3:
            break
        step = _rigid_fit(moved[pairs], target[nearest[pairs]])
        pose = se2.compose(step, pose)
        if math.hypot(step[0], step[1]) < 1e-4 and abs(step[2]) < 1e-5:
            break
    distance, _ = tree.query(se2.transform_points(pose, source))
    inliers = distance <= inlier_m
    rmse = float(np.sqrt(np.mean(distance[inliers] ** 2))) if inliers.any() else math.inf
    return ScanMatch(pose, rmse, float(inliers.mean()), ambiguity)


class Alignment(NamedTuple):
    """Result of :func:`align_scans`.

    ``pose`` (3,) maps source points into the target frame. ``information`` (3, 3) is the inverse
    covariance of that pose in the source frame's tangent space (x, y metres, yaw radians; GTSAM's
    ``Pose2`` convention), from the point-to-line residuals alone: large across a surface and in yaw,
    near zero along a featureless wall. ``rmse_m`` is the RMS residual of the inlier pairs and
    ``inlier_fraction`` the share of source points within ``inlier_m`` of a target point.
    """

    pose: npt.NDArray[np.float64]
    information: npt.NDArray[np.float64]
    rmse_m: float
    inlier_fraction: float


def _surface_weights(target: npt.NDArray[np.float64], tree: cKDTree, *, neighbours: int, radius_m: float,
                     max_flatness: float) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """Per target point an anchor (2,) and a (2, 2) residual weight.

    On a locally straight surface the anchor is the neighbours' centroid and the weight ``n n^T``
    (distance to the fitted line); elsewhere (an upright's corner, a lone point) the point itself and
    the identity.
    """
    distance, index = tree.query(target, k=neighbours, distance_upper_bound=radius_m)
    found = np.isfinite(distance)
    near = target[np.minimum(index, target.shape[0] - 1)]
    count = found.sum(axis=1)
    mean = np.sum(np.where(found[..., None], near, 0.0), axis=1) / count[:, None]
    d = np.where(found[..., None], near - mean[:, None, :], 0.0)
    cov = np.einsum("nki,nkj->nij", d, d) / count[:, None, None]
    values, vectors = np.linalg.eigh(cov)
    normal = vectors[:, :, 0]
    straight = (count >= 3) & (values[:, 0] <= max_flatness * values[:, 1])
    weights = np.broadcast_to(np.eye(2), (target.shape[0], 2, 2)).copy()
    weights[straight] = np.einsum("ni,nj->nij", normal[straight], normal[straight])
    return np.where(straight[:, None], mean, target), weights


def align_scans(
    source_xy: npt.ArrayLike,
    target_xy: npt.ArrayLike,
    *,
    initial_pose: npt.ArrayLike,
    prior_information: npt.ArrayLike | None = None,
    max_correspondence_m: float = 0.2,
    inlier_m: float = 0.1,
    robust_m: float = 0.03,
    noise_m: float = 0.01,
    neighbours: int = 6,
    radius_m: float = 0.3,
    max_flatness: float = 0.05,
    max_iterations: int = 20,
) -> Alignment:
    """Refine ``initial_pose`` of ``source`` in ``target`` by point-to-line ICP, with its information matrix.

    For use when the initial pose is already close (odometry between consecutive keyframes, or a
    :func:`match_scans` result): no search, only Gauss-Newton on the distances of source points to
    the straight surface through their nearest target point (to the point itself where the target is
    not locally straight, e.g. at an upright's corner), with Cauchy weights of width ``robust_m``
    against outliers. ``prior_information`` (3, 3), optional, pulls the pose towards
    ``initial_pose`` (in its tangent space), so a direction the points leave open (along a wall)
    stays where odometry put it; it is not part of the returned ``information``. The residual
    variance behind ``information`` is the inliers' mean squared residual, at least ``noise_m``
    squared.

    Raises
    ------
    SemanticFusionError
        Fewer than 3 points on either side, non-finite input, or non-positive distances.
    """
    source = np.asarray(source_xy, dtype=np.float64).reshape(-1, 2)
    target = np.asarray(target_xy, dtype=np.float64).reshape(-1, 2)
    initial = np.asarray(initial_pose, dtype=np.float64).reshape(3)
    prior = np.zeros((3, 3)) if prior_information is None else np.asarray(prior_information, dtype=np.float64)
    if source.shape[0] < 3 or target.shape[0] < 3:
        raise SemanticFusionError(f"scan alignment needs >= 3 points a side, got {source.shape[0]}, {target.shape[0]}")
    if not (np.all(np.isfinite(source)) and np.all(np.isfinite(target)) and np.all(np.isfinite(initial))
            and prior.shape == (3, 3) and np.all(np.isfinite(prior))):
        raise SemanticFusionError("scan alignment input must be finite (prior information (3, 3))")
    distances = (max_correspondence_m, inlier_m, robust_m, noise_m, radius_m, max_flatness)
    if min(distances) <= 0 or min(neighbours - 2, max_iterations) < 1:
        raise SemanticFusionError("alignment distances must be positive, neighbours >= 3, max_iterations >= 1")
    tree = cKDTree(target)
    anchors, surface = _surface_weights(target, tree, neighbours=neighbours, radius_m=radius_m,
                                        max_flatness=max_flatness)
    pose = initial.copy()
    hessian = np.zeros((3, 3))
    for _ in range(max_iterations + 1):
        moved = se2.transform_points(pose, source)
        distance, nearest = tree.query(moved, distance_upper_bound=max_correspondence_m)
        pairs = np.flatnonzero(np.isfinite(distance))
        if pairs.size < 3:
            raise SemanticFusionError(f"scan alignment lost its correspondences ({pairs.size} pairs)")
        error = moved[pairs] - anchors[nearest[pairs]]
        weight = surface[nearest[pairs]]
        squared = np.einsum("ni,nij,nj->n", error, weight, error)
        robust = 1.0 / (1.0 + squared / robust_m**2)
        c, s = math.cos(pose[2]), math.sin(pose[2])
        jac = np.zeros((pairs.size, 2, 3))
        jac[:, :, :2] = np.array([[c, -s], [s, c]])
        jac[:, :, 2] = np.column_stack([pose[1] - moved[pairs, 1], moved[pairs, 0] - pose[0]])
        weighted = np.einsum("nij,njk->nik", weight, jac) * robust[:, None, None]
        hessian = np.einsum("nij,nik->jk", jac, weighted)
        gradient = np.einsum("nij,ni->j", weighted, error)
        offset = se2.between(initial, pose)
        step = -np.linalg.solve(hessian / noise_m**2 + prior + 1e-9 * np.eye(3),
                                gradient / noise_m**2 + prior @ offset)
        if math.hypot(step[0], step[1]) < 1e-5 and abs(step[2]) < 1e-6:
            break
        pose = se2.compose(pose, step)
    distance, _ = tree.query(se2.transform_points(pose, source))
    inliers = distance <= inlier_m
    variance = max(float(np.sum(robust * squared) / np.sum(robust)), noise_m**2)
    rmse = float(np.sqrt(np.mean(squared[squared <= inlier_m**2]))) if np.any(squared <= inlier_m**2) else math.inf
    return Alignment(pose, hessian / variance, rmse, float(inliers.mean()))
