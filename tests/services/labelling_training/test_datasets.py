from __future__ import annotations

from collections import defaultdict
from pathlib import Path

import numpy as np
import pytest

from services.labelling_training import YoloSet, in_test_split, read_scene_labels, roi_crops, source_of
from services.object_labelling import ObjectLabellingError
from tests.helpers import data_path

SCENE_LABELS = Path(__file__).resolve().parents[3] / "services" / "labelling_training" / "data" / "scene_labels.csv"


def test_source_of_strips_the_roboflow_augmentation_suffix() -> None:
    assert source_of("01FVZIGPUGWI_jpg.rf.272f9ea3336a11f2c4390ccc97244242.jpg") == "01FVZIGPUGWI_jpg"
    assert source_of("plain_photo.png") == "plain_photo"


def test_split_keeps_every_augmentation_of_a_source_together() -> None:
    images = data_path("images", "forklift_person", "train", "images")
    splits: dict[str, set[bool]] = defaultdict(set)
    for path in images.iterdir():
        source = source_of(path.name)
        splits[source].add(in_test_split(source, test_fraction=0.3))
    assert all(len(s) == 1 for s in splits.values())
    share = np.mean([next(iter(s)) for s in splits.values()])
    assert 0.2 < share < 0.4


def test_scene_label_list_names_real_photos_with_binary_labels() -> None:
    images = data_path("images", "pallets", "train", "images")
    rows = read_scene_labels(SCENE_LABELS)
    assert len(rows) >= 100
    assert all((images / name).is_file() for name, _ in rows)
    assert {tuple(sorted(labels)) for _, labels in rows} == {("gate", "rack")}


def test_roi_crops_cut_labelled_boxes_and_background_away_from_them(tmp_path: Path) -> None:
    import cv2

    (tmp_path / "images").mkdir()
    (tmp_path / "labels").mkdir()
    image = np.zeros((100, 200, 3), np.uint8)
    image[20:60, 40:80] = (255, 0, 0)
    cv2.imwrite(str(tmp_path / "images" / "a_jpg.rf.1.png"), image[:, :, ::-1])
    (tmp_path / "labels" / "a_jpg.rf.1.txt").write_text("0 0.3 0.4 0.2 0.4\n1 0.9 0.9 0.02 0.02\n")
    crops = list(roi_crops(YoloSet(tmp_path, {0: "pallet", 1: "human"}), negatives_per_image=3))
    pallets = [c for c in crops if c.label == "pallet"]
    assert len(pallets) == 1 and not [c for c in crops if c.label == "human"]  # the 4 px box is too small
    assert pallets[0].image[..., 0].mean() > 150 and pallets[0].source == "a_jpg"
    backgrounds = [c for c in crops if c.label == "background"]
    assert backgrounds and all(c.image[..., 0].mean() < 128 for c in backgrounds)


def test_read_scene_labels_rejects_non_binary_labels(tmp_path: Path) -> None:
    path = tmp_path / "labels.csv"
    path.write_text("filename,rack,gate\na.jpg,1,2\n")
    with pytest.raises(ObjectLabellingError, match="0 or 1"):
        read_scene_labels(path)
