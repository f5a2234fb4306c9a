"""Camera sensors: a downward-looking equidistant fisheye and a sideways RGB-D camera.

The fisheye renders five pinhole cube faces (down, and the four sides down to 45 degrees above
the horizon) and remaps them through the equidistant model ``r = f * theta``; vertical uprights
then appear as radial bars pointing at the image centre (the nadir), as in the warehouse
pillar-mapping papers. The RGB-D camera renders colour and depth from one viewpoint (registered),
with range-dependent depth noise, in millimetres.
"""

from __future__ import annotations

import logging
import math
from functools import lru_cache
from pathlib import Path
from typing import NamedTuple

import cv2
import numpy as np
import numpy.typing as npt
from rosbags.typesys.stores.ros2_jazzy import sensor_msgs__msg__CameraInfo as CameraInfo
from rosbags.typesys.stores.ros2_jazzy import sensor_msgs__msg__Image as Image

from services.simulator import rosmsgs
from services.simulator.actors import dynamic_boxes
from services.simulator.render import PinholeCamera, Rendered, Textures, render_boxes
from services.simulator.stream import CameraSensor
from services.simulator.world import Boxes, FloatArray, ObjectClass, World, concat_boxes

log = logging.getLogger(__name__)

FISHEYE_FRAME = "fisheye_optical_frame"
RGBD_FRAME = "rgbd_optical_frame"
IMAGES_DIR = Path(__file__).resolve().parents[3] / "shared" / "data" / "images"
"""Photos with YOLO boxes used to texture pallets, forklifts and people when present."""


class FisheyeModel(NamedTuple):
    """An equidistant fisheye: square image of ``size`` pixels, field of view, cube-face resolution."""

    size: int = 480
    fov_rad: float = math.radians(185.0)
    face_size: int = 192
    far_m: float = 12.0
    """Boxes farther than this (horizontally) are left out; they would be a few pixels at the rim."""

    @property
    def focal_px(self) -> float:
        """f of r = f * theta, pixels: the field of view just fills the image circle."""
        return 0.5 * self.size / (0.5 * self.fov_rad)

    def k(self) -> FloatArray:
        """Intrinsic matrix (for CameraInfo, distortion model ``equidistant`` with zero coefficients)."""
        c = 0.5 * (self.size - 1)
        return np.array([[self.focal_px, 0.0, c], [0.0, self.focal_px, c], [0.0, 0.0, 1.0]])


def _axis_rotation(axis: tuple[float, float, float], angle_rad: float) -> FloatArray:
    rotation, _ = cv2.Rodrigues(np.array(axis, np.float64) * angle_rad)
    return np.asarray(rotation, np.float64)


# fisheye optical frame -> cube face optical frames: down (the optical axis), +x, -x, +y, -y
_CUBE = (np.eye(3), _axis_rotation((0, 1, 0), math.pi / 2), _axis_rotation((0, 1, 0), -math.pi / 2),
         _axis_rotation((1, 0, 0), -math.pi / 2), _axis_rotation((1, 0, 0), math.pi / 2))


@lru_cache(maxsize=4)
def _fisheye_maps(model: FisheyeModel) -> tuple[npt.NDArray[np.float32], npt.NDArray[np.float32],
                                                npt.NDArray[np.bool_]]:
    """cv2.remap maps from the fisheye image into the five faces laid side by side, and the image circle."""
    n, s = model.size, model.face_size
    c = 0.5 * (n - 1)
    v, u = np.mgrid[0:n, 0:n].astype(np.float64)
    dx, dy = u - c, v - c
    theta = np.hypot(dx, dy) / model.focal_px
    phi = np.arctan2(dy, dx)
    rays = np.stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)], axis=-1)
    in_face = np.stack([rays @ r for r in _CUBE])  # (5, n, n, 3) ray in each face's frame
    face = np.argmax(in_face[..., 2], axis=0)
    chosen = np.take_along_axis(in_face, face[None, ..., None], axis=0)[0]
    f = 0.5 * s
    map_x = (face * s + np.clip(f * chosen[..., 0] / chosen[..., 2] + 0.5 * (s - 1), 0, s - 1)).astype(np.float32)
    map_y = np.clip(f * chosen[..., 1] / chosen[..., 2] + 0.5 * (s - 1), 0, s - 1).astype(np.float32)
    return map_x, map_y, theta <= 0.5 * model.fov_rad


def render_fisheye(boxes: Boxes, world_from_optical: FloatArray, model: FisheyeModel, *,
                   textures: Textures | None = None) -> tuple[npt.NDArray[np.uint8], npt.NDArray[np.int8]]:
    """Fisheye colour image (size, size, 3) uint8 and class image (int8, -1 outside the circle or
    nothing) seen from ``world_from_optical`` (optical z along the lens axis)."""
    s = model.face_size
    face_camera = PinholeCamera(0.5 * s, 0.5 * s, 0.5 * (s - 1), 0.5 * (s - 1), s, s)
    faces: list[Rendered] = []
    for rotation in _CUBE:
        pose = world_from_optical.copy()
        pose[:3, :3] = world_from_optical[:3, :3] @ rotation
        faces.append(render_boxes(boxes, pose, face_camera, far_m=model.far_m, textures=textures))
    atlas = np.concatenate([f.rgb for f in faces], axis=1)
    kinds = np.concatenate([f.kind for f in faces], axis=1)
    map_x, map_y, circle = _fisheye_maps(model)
    rgb = cv2.remap(atlas, map_x, map_y, cv2.INTER_LINEAR)
    kind = cv2.remap(kinds, map_x, map_y, cv2.INTER_NEAREST)
    rgb[~circle] = 0
    kind[~circle] = -1
    return np.asarray(rgb, np.uint8), np.asarray(kind, np.int8)


class RgbdModel(NamedTuple):
    """A structured-light RGB-D camera (Asus Xtion-like): 640x480, 58 degrees, 0.4-5 m."""

    width: int = 640
    height: int = 480
    horizontal_fov_rad: float = math.radians(58.0)
    min_range_m: float = 0.4
    max_range_m: float = 5.0

    def camera(self) -> PinholeCamera:
        """The pinhole intrinsics of both streams."""
        return PinholeCamera.from_fov(self.width, self.height, self.horizontal_fov_rad)


def depth_image_mm(depth_m: npt.NDArray[np.float32], model: RgbdModel, rng: np.random.Generator
                   ) -> npt.NDArray[np.uint16]:
    """16UC1 depth in millimetres with axial noise sigma(z) = 1.2 mm + 1.9 mm * (z - 0.4 m)^2 per
    metre squared (Kinect-class), 0 where out of range or nothing."""
    valid = np.isfinite(depth_m) & (depth_m >= model.min_range_m) & (depth_m <= model.max_range_m)
    z = np.where(valid, depth_m, 0.0)
    sigma = 0.0012 + 0.0019 * (z - 0.4) ** 2
    noisy = z + rng.normal(0.0, 1.0, z.shape) * sigma
    return np.where(valid, np.round(noisy * 1000.0), 0).astype(np.uint16)


def _yolo_crops(folder: Path, class_ids: dict[int, int], *, limit: int, size: int
                ) -> dict[int, list[npt.NDArray[np.float32]]]:
    """Up to ``limit`` crops per object class from YOLO-labelled photos under ``folder``."""
    crops: dict[int, list[npt.NDArray[np.float32]]] = {cls: [] for cls in class_ids.values()}
    for label_file in sorted((folder / "train" / "labels").glob("*.txt")):
        if all(len(v) >= limit for v in crops.values()):
            break
        image_path = next(iter((folder / "train" / "images").glob(label_file.stem + ".*")), None)
        if image_path is None:
            continue
        image = cv2.imread(str(image_path))
        if image is None:
            continue
        h, w = image.shape[:2]
        for line in label_file.read_text().splitlines():
            parts = line.split()
            if len(parts) != 5 or int(parts[0]) not in class_ids:
                continue
            cls = class_ids[int(parts[0])]
            cx, cy, bw, bh = (float(p) for p in parts[1:])
            x0, x1 = int((cx - bw / 2) * w), int((cx + bw / 2) * w)
            y0, y1 = int((cy - bh / 2) * h), int((cy + bh / 2) * h)
            if len(crops[cls]) >= limit or x1 - x0 < 24 or y1 - y0 < 24:
                continue
            crop = cv2.resize(image[max(y0, 0):y1, max(x0, 0):x1], (size, size), interpolation=cv2.INTER_AREA)
            crops[cls].append(crop[:, :, ::-1].astype(np.float32) / 255.0)
    return crops


@lru_cache(maxsize=2)
def photo_textures(images_dir: Path = IMAGES_DIR, *, per_class: int = 24, size: int = 64) -> Textures | None:
    """Crops of real photos for pallets, forklifts and people, or None when the photos are absent."""
    sources = ((images_dir / "pallets", {0: int(ObjectClass.PALLET)}),
               (images_dir / "forklift_person", {0: int(ObjectClass.FORKLIFT), 1: int(ObjectClass.PERSON)}))
    atlas: list[npt.NDArray[np.float32]] = []
    by_class: dict[int, npt.NDArray[np.int64]] = {}
    for folder, ids in sources:
        if not folder.is_dir():
            continue
        for cls, crops in _yolo_crops(folder, ids, limit=per_class, size=size).items():
            by_class[cls] = np.arange(len(atlas), len(atlas) + len(crops))
            atlas += crops
    if not atlas:
        log.info("no photos under %s: procedural textures only", images_dir)
        return None
    return Textures(np.stack(atlas), by_class)


def _scene(world: World, time_s: float) -> Boxes:
    return concat_boxes([world.boxes, dynamic_boxes(world, time_s)])


def _mount(rotation_columns: tuple[tuple[float, ...], ...], translation: tuple[float, float, float]) -> FloatArray:
    mount = np.eye(4)
    mount[:3, :3] = np.array(rotation_columns, dtype=np.float64).T
    mount[:3, 3] = translation
    return mount


FISHEYE_MOUNT = _mount(((0.0, -1.0, 0.0), (-1.0, 0.0, 0.0), (0.0, 0.0, -1.0)), (0.0, 0.0, 2.5))
"""base_link -> fisheye optical frame: 2.5 m up, looking straight down, image up = robot forward."""
RGBD_MOUNT = _mount(((1.0, 0.0, 0.0), (0.0, 0.0, -1.0), (0.0, 1.0, 0.0)), (0.0, 0.35, 1.0))
"""base_link -> RGB-D optical frame: 1 m up on the left side, looking left, level."""


def rack_rgbd_mount(*, height_m: float = 1.0, pitch_up_rad: float = 0.0) -> FloatArray:
    """base_link -> optical frame of a rack-facing RGB-D camera on a mast: on the left side, looking left at
    the rack face across the aisle, ``height_m`` up and pitched up by ``pitch_up_rad`` (a pair, low and high,
    sees the levels of a rack; :data:`RGBD_MOUNT` is the level one at 1 m)."""
    c, s = math.cos(pitch_up_rad), math.sin(pitch_up_rad)
    return _mount(((1.0, 0.0, 0.0), (0.0, s, -c), (0.0, c, s)), (0.0, 0.35, height_m))


def fisheye_sensor(*, rate_hz: float = 5.0, model: FisheyeModel | None = None, photos: bool = True) -> CameraSensor:
    """The downward fisheye as a :class:`CameraSensor` on ``fisheye/image_raw`` and ``fisheye/camera_info``."""
    model = model or FisheyeModel()
    textures = photo_textures() if photos else None

    def render(world: World, time_s: float, optical: FloatArray, stamp_ns: int, frame: str
               ) -> list[tuple[str, str, Image | CameraInfo]]:
        rgb, _ = render_fisheye(_scene(world, time_s), optical, model, textures=textures)
        return [("fisheye/image_raw", *rosmsgs.image(stamp_ns, frame, rgb)),
                ("fisheye/camera_info", *rosmsgs.camera_info(stamp_ns, frame, width=model.size, height=model.size,
                                                             k=model.k(), distortion_model="equidistant",
                                                             d=(0.0, 0.0, 0.0, 0.0)))]

    return CameraSensor("fisheye", rate_hz, FISHEYE_MOUNT, FISHEYE_FRAME, render)


def rgbd_sensor(*, rate_hz: float = 5.0, model: RgbdModel | None = None, photos: bool = True,
                seed: int = 0, mount: FloatArray | None = None) -> CameraSensor:
    """The sideways RGB-D camera on ``rgbd/color/image_raw`` (rgb8), ``rgbd/depth/image_raw``
    (16UC1, mm) and ``rgbd/camera_info``, mounted at ``mount`` (base_link -> optical, default
    :data:`RGBD_MOUNT`; :func:`rack_rgbd_mount` for a rack-facing mast camera)."""
    model = model or RgbdModel()
    camera = model.camera()
    textures = photo_textures() if photos else None
    rng = np.random.default_rng(seed)

    def render(world: World, time_s: float, optical: FloatArray, stamp_ns: int, frame: str
               ) -> list[tuple[str, str, Image | CameraInfo]]:
        rendered = render_boxes(_scene(world, time_s), optical, camera, textures=textures)
        depth = depth_image_mm(rendered.depth_m, model, rng)
        return [("rgbd/color/image_raw", *rosmsgs.image(stamp_ns, frame, rendered.rgb)),
                ("rgbd/depth/image_raw", *rosmsgs.image(stamp_ns, frame, depth)),
                ("rgbd/camera_info", *rosmsgs.camera_info(stamp_ns, frame, width=model.width, height=model.height,
                                                          k=camera.k()))]

    return CameraSensor("rgbd", rate_hz, RGBD_MOUNT if mount is None else mount, RGBD_FRAME, render)
