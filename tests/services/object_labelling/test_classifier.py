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
        rng.uniform(0.5, 2.0, len(classes)).astype(np.float32),
        rng.normal(size=len(classes)).astype(np.float32),
    )


def random_model(seed: int = 0, input_size_px: int = 128) -> LabelModel:
    return LabelModel(
        random_bank(("pallet", "forklift", "human"), seed=seed),
        random_bank(("rack", "gate"), seed=seed + 1),
        input_size_px,
        "ab" * 32,
        0.6,
    )


def test_model_file_round_trips(tmp_path: Path) -> None:
    model = random_model()
    model.save(tmp_path / "m.npz")
    loaded = LabelModel.load(tmp_path / "m.npz")
    features = np.random.default_rng(1).random((4, 1280), dtype=np.float32)
    scores = model.roi.scores(features)
    np.testing.assert_allclose(loaded.roi.scores(features), scores, rtol=1e-6)
    np.testing.assert_allclose(loaded.roi.probabilities(scores), model.roi.probabilities(scores), rtol=1e-6)
    assert (loaded.roi.classes, loaded.scene.classes) == (model.roi.classes, model.scene.classes)
    assert (loaded.input_size_px, loaded.weights_sha256, loaded.min_probability) == (128, "ab" * 32, 0.6)


def test_model_load_reports_missing_and_corrupt_files(tmp_path: Path) -> None:
    with pytest.raises(ObjectLabellingError, match="does not exist"):
        LabelModel.load(tmp_path / "none.npz")
    (tmp_path / "bad.npz").write_bytes(b"PK\x03\x04 not really a zip")
    with pytest.raises(ObjectLabellingError, match="corrupt"):
        LabelModel.load(tmp_path / "bad.npz")
    np.savez(tmp_path / "other.npz", header=np.array('{"format": "something else", "version": 1}'))
    with pytest.raises(ObjectLabellingError, match="expected aisle-object-labelling-svm"):
        LabelModel.load(tmp_path / "other.npz")
    np.savez(tmp_path / "v1.npz", header=np.array('{"format": "aisle-object-labelling-svm", "version": 1}'))
    with pytest.raises(ObjectLabellingError, match=r"v2 \(retrain it\)"):
        LabelModel.load(tmp_path / "v1.npz")


def test_best_class_says_unknown_below_the_threshold() -> None:
    probabilities = np.array([[0.9, 0.1], [0.4, 0.3], [0.55, 0.6]], dtype=np.float32)
    assert best_class(probabilities, ("a", "b"), min_probability=0.5) == ["a", UNKNOWN, "b"]


def test_probabilities_rise_with_the_svm_score() -> None:
    bank = random_bank(("a", "b"), dim=4)
    scores = np.array([[-3.0, -3.0], [0.0, 0.0], [3.0, 3.0]], dtype=np.float32)
    p = bank.probabilities(scores)
    assert ((p > 0) & (p < 1)).all() and (np.diff(p, axis=0) > 0).all()


def test_bank_rejects_mismatched_shapes_and_feature_sizes() -> None:
    bank = random_bank(("a",), dim=8)
    with pytest.raises(ObjectLabellingError, match=r"features must be \(n, 8\)"):
        bank.scores(np.zeros((1, 9), np.float32))
    with pytest.raises(ObjectLabellingError, match="shapes disagree"):
        SvmBank(("a", "b"), bank.coef, bank.intercept, bank.mean, bank.scale, bank.platt_a, bank.platt_b)
    with pytest.raises(ObjectLabellingError, match="Platt"):
        SvmBank(("a",), bank.coef, bank.intercept, bank.mean, bank.scale, -bank.platt_a, bank.platt_b)
