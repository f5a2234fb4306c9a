from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from services.object_labelling import UNKNOWN, LabelModel, ObjectLabellingError, SvmBank, best_class


def random_bank(classes: tuple[str, ...], dim: int = 1280, seed: int = 0) -> SvmBank:
    rng = np.random.default_rng(seed)
    return SvmBank(
        classes,
        rng.normal(size=(len(classes), dim)).astype(np.float32),
        rng.normal(size=len(classes)).astype(np.float32),
        rng.random(dim).astype(np.float32),
        rng.uniform(0.5, 2.0, dim).astype(np.float32),
    )


def random_model(seed: int = 0, input_size_px: int = 128) -> LabelModel:
    return LabelModel(
        random_bank(("pallet", "forklift", "human"), seed=seed),
        random_bank(("rack", "gate"), seed=seed + 1),
        input_size_px,
        "ab" * 32,
        0.25,
    )


def test_model_file_round_trips(tmp_path: Path) -> None:
    model = random_model()
    model.save(tmp_path / "m.npz")
    loaded = LabelModel.load(tmp_path / "m.npz")
    features = np.random.default_rng(1).random((4, 1280), dtype=np.float32)
    np.testing.assert_allclose(loaded.roi.scores(features), model.roi.scores(features), rtol=1e-6)
    assert (loaded.roi.classes, loaded.scene.classes) == (model.roi.classes, model.scene.classes)
    assert (loaded.input_size_px, loaded.weights_sha256, loaded.min_score) == (128, "ab" * 32, 0.25)


def test_model_load_reports_missing_and_corrupt_files(tmp_path: Path) -> None:
    with pytest.raises(ObjectLabellingError, match="does not exist"):
        LabelModel.load(tmp_path / "none.npz")
    (tmp_path / "bad.npz").write_bytes(b"PK\x03\x04 not really a zip")
    with pytest.raises(ObjectLabellingError, match="corrupt"):
        LabelModel.load(tmp_path / "bad.npz")
    np.savez(tmp_path / "other.npz", header=np.array('{"format": "something else", "version": 1}'))
    with pytest.raises(ObjectLabellingError, match="expected aisle-object-labelling-svm"):
        LabelModel.load(tmp_path / "other.npz")


def test_best_class_says_unknown_below_the_threshold() -> None:
    scores = np.array([[0.9, -1.0], [-0.2, -0.5], [0.1, 0.3]], dtype=np.float32)
    assert best_class(scores, ("a", "b"), min_score=0.0) == ["a", UNKNOWN, "b"]


def test_bank_rejects_mismatched_shapes_and_feature_sizes() -> None:
    bank = random_bank(("a",), dim=8)
    with pytest.raises(ObjectLabellingError, match=r"features must be \(n, 8\)"):
        bank.scores(np.zeros((1, 9), np.float32))
    with pytest.raises(ObjectLabellingError, match="shapes disagree"):
        SvmBank(("a", "b"), bank.coef, bank.intercept, bank.mean, bank.scale)
