"""Training samples from YOLO-labelled photo sets and the whole-image label list.

Augmented copies of one photo must never straddle the train/test split, so every sample carries
its source name (Roboflow file names encode it before ``.rf.``) and the split is a stable hash of
that name.
"""

from __future__ import annotations

import csv
import hashlib
from collections.abc import Iterator
from pathlib import Path
from typing import NamedTuple

import cv2
import numpy as np
import numpy.typing as npt

from services.object_labelling.crops import ROI_PAD_FRACTION
from services.object_labelling.errors import ObjectLabellingError

BACKGROUND = "background"
IMAGE_SUFFIXES = (".jpg", ".jpeg", ".png")


class YoloSet(NamedTuple):
    """A YOLO folder (``images/`` and ``labels/`` inside ``root``) and what its class ids mean to us."""

    root: Path
    classes: dict[int, str]


class Crop(NamedTuple):
    """One training sample: an RGB image region, its class and the source photo it came from."""

    image: npt.NDArray[np.uint8]
    label: str
    source: str


class Samples(NamedTuple):
    """Labelled samples for both SVM banks.

    ``crops`` for the ROI classes (and background); ``scene_images`` whole images with a 0/1
    label per whole-image class in ``scene_labels`` (class -> (n,) int64) and their source names
    in ``scene_sources`` (samples of one source stay on one side of every split).
    """

    crops: list[Crop]
    scene_images: list[npt.NDArray[np.uint8]]
    scene_labels: dict[str, npt.NDArray[np.int64]]
    scene_sources: list[str]

    @classmethod
    def concat(cls, parts: list[Samples]) -> Samples:
        """All samples of ``parts``; their whole-image classes must agree."""
        names = {tuple(p.scene_labels) for p in parts}
        if len(names) > 1:
            raise ObjectLabellingError(f"samples disagree on the whole-image classes: {sorted(names)}")
        classes = next(iter(names), ())
        return cls(
            [c for p in parts for c in p.crops],
            [i for p in parts for i in p.scene_images],
            {c: np.concatenate([p.scene_labels[c] for p in parts]).astype(np.int64) for c in classes},
            [s for p in parts for s in p.scene_sources],
        )


def source_of(filename: str) -> str:
    """The source photo of a (possibly Roboflow-augmented) file name: the part before ``.rf.``.

    >>> source_of("01FVZIGPUGWI_jpg.rf.272f9ea3.jpg")
    '01FVZIGPUGWI_jpg'
    """
    name = Path(filename).name
    return name.split(".rf.", 1)[0] if ".rf." in name else Path(name).stem


def in_test_split(source: str, *, test_fraction: float, seed: int = 0) -> bool:
    """Whether ``source`` falls in the held-out split: a stable hash, independent of file order."""
    digest = hashlib.sha256(f"{seed}:{source}".encode()).digest()
    return int.from_bytes(digest[:8], "big") / 2.0**64 < test_fraction


def read_rgb(path: Path) -> npt.NDArray[np.uint8]:
    """An image file as (h, w, 3) uint8 RGB."""
    image = cv2.imread(str(path), cv2.IMREAD_COLOR)
    if image is None:
        raise ObjectLabellingError(f"cannot read image {path}")
    return np.ascontiguousarray(image[:, :, ::-1])


def _boxes(label_path: Path, width: int, height: int) -> list[tuple[int, int, int, int, int]]:
    """(class id, x0, y0, x1, y1) pixel boxes of a YOLO label file (absent file = no boxes)."""
    if not label_path.is_file():
        return []
    boxes = []
    for line_no, line in enumerate(label_path.read_text().splitlines(), 1):
        parts = line.split()
        if not parts:
            continue
        if len(parts) != 5:
            raise ObjectLabellingError(f"{label_path}:{line_no}: expected 5 fields, got {len(parts)}")
        cls, xc, yc, w, h = int(parts[0]), *map(float, parts[1:])
        boxes.append(
            (
                cls,
                int((xc - w / 2) * width),
                int((yc - h / 2) * height),
                int(np.ceil((xc + w / 2) * width)),
                int(np.ceil((yc + h / 2) * height)),
            )
        )
    return boxes


def _iou(box: npt.NDArray[np.float64], others: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    ix = np.clip(np.minimum(box[2], others[:, 2]) - np.maximum(box[0], others[:, 0]), 0, None)
    iy = np.clip(np.minimum(box[3], others[:, 3]) - np.maximum(box[1], others[:, 1]), 0, None)
    inter = ix * iy
    area = (box[2] - box[0]) * (box[3] - box[1])
    return np.asarray(inter / (area + (others[:, 2] - others[:, 0]) * (others[:, 3] - others[:, 1]) - inter))


def roi_crops(
    dataset: YoloSet,
    *,
    min_box_px: int = 20,
    pad_fraction: float = ROI_PAD_FRACTION,
    negatives_per_image: int = 1,
    max_negative_iou: float = 0.1,
    seed: int = 0,
) -> Iterator[Crop]:
    """Padded crops of every labelled box at least ``min_box_px`` on each side, plus background crops.

    Background crops are random boxes (sides 15-50 % of the image) overlapping no labelled box by
    more than ``max_negative_iou``; they are labelled ``"background"``.
    """
    images = sorted(p for p in (dataset.root / "images").iterdir() if p.suffix.lower() in IMAGE_SUFFIXES)
    if not images:
        raise ObjectLabellingError(f"no images in {dataset.root / 'images'}")
    rng = np.random.default_rng(seed)
    for path in images:
        image = read_rgb(path)
        height, width = image.shape[:2]
        source = source_of(path.name)
        boxes = _boxes(dataset.root / "labels" / f"{path.stem}.txt", width, height)
        for cls, x0, y0, x1, y1 in boxes:
            if cls not in dataset.classes or min(x1 - x0, y1 - y0) < min_box_px:
                continue
            px, py = int(pad_fraction * (x1 - x0)), int(pad_fraction * (y1 - y0))
            crop = image[max(y0 - py, 0) : min(y1 + py, height), max(x0 - px, 0) : min(x1 + px, width)]
            yield Crop(crop, dataset.classes[cls], source)
        taken = np.array([b[1:] for b in boxes], dtype=np.float64).reshape(-1, 4)
        for _ in range(negatives_per_image):
            for _attempt in range(20):
                w, h = rng.uniform(0.15, 0.5, 2) * (width, height)
                x0, y0 = rng.uniform(0, width - w), rng.uniform(0, height - h)
                box = np.array([x0, y0, x0 + w, y0 + h])
                if taken.size == 0 or _iou(box, taken).max() <= max_negative_iou:
                    yield Crop(image[int(y0) : int(y0 + h), int(x0) : int(x0 + w)], BACKGROUND, source)
                    break


def read_scene_labels(csv_path: Path) -> list[tuple[str, dict[str, int]]]:
    """Rows of a ``filename,<class>,<class>...`` CSV of 0/1 whole-image labels."""
    with csv_path.open(newline="") as stream:
        reader = csv.DictReader(stream)
        if reader.fieldnames is None or reader.fieldnames[0] != "filename" or len(reader.fieldnames) < 2:
            raise ObjectLabellingError(f"{csv_path} must start with a 'filename,<class>...' header")
        rows = []
        for row in reader:
            try:
                labels = {name: int(row[name]) for name in reader.fieldnames[1:]}
            except (TypeError, ValueError) as err:
                raise ObjectLabellingError(f"{csv_path}: bad label in row {row}") from err
            if any(v not in (0, 1) for v in labels.values()):
                raise ObjectLabellingError(f"{csv_path}: labels must be 0 or 1, row {row}")
            rows.append((row["filename"], labels))
    return rows
