"""Fitting the SVM banks: calibrated probabilities and clear errors for unusable training sets."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
import pytest

from services.labelling_training.training import fit_bank
from services.object_labelling import ObjectLabellingError


def _draw(rng: np.random.Generator, n: int) -> tuple[npt.NDArray[np.float32], npt.NDArray[np.bool_]]:
    """Two overlapping Gaussian classes in 16-d, 30 % positives (Bayes error about 12 %)."""
    y = rng.random(n) < 0.3
    x = rng.normal(size=(n, 16))
    x[:, 0] += 2.0 * y
    return x.astype(np.float32), y


def test_probabilities_match_the_frequencies_on_held_out_samples() -> None:
    rng = np.random.default_rng(0)
    x, y = _draw(rng, 1200)
    bank = fit_bank(x, {"a": y}, (np.arange(y.size) // 4).astype(str), (1e-3, 1e-2))
    x_test, y_test = _draw(rng, 20000)
    p = bank.probabilities(bank.scores(x_test))[:, 0]
    bins = np.digitize(p, np.linspace(0.1, 0.9, 9))
    calibration_error = sum(
        abs(p[bins == b].mean() - y_test[bins == b].mean()) * (bins == b).mean() for b in np.unique(bins)
    )
    assert calibration_error < 0.04  # expected calibration error over ten probability bins
    assert ((p >= 0.5) == y_test).mean() > 0.84  # close to the Bayes rate at the 0.5 threshold


def test_training_sets_without_negatives_or_with_too_few_sources_are_refused() -> None:
    x = np.random.default_rng(1).normal(size=(30, 4)).astype(np.float32)
    with pytest.raises(ObjectLabellingError, match="no negatives"):
        fit_bank(x, {"a": np.ones(30, bool)}, np.arange(30).astype(str), (1e-2,))
    with pytest.raises(ObjectLabellingError, match="from 1 sources; cross-validation needs at least 3"):
        fit_bank(x, {"a": np.arange(30) % 2 == 0}, np.array(["s1", "s2"] * 15), (1e-2,))
