from __future__ import annotations

import numpy as np
import pytest

from services.object_labelling import EfficientNetLite0, ObjectLabellingError, resize_for_cnn
from services.object_labelling.cnn import _Conv, _depthwise, _same_padding, _stem

CAT_CLASSES = set(range(281, 286))  # tabby, tiger cat, Persian, Siamese, Egyptian cat
CUP_CLASSES = {967, 968}  # espresso, cup


def _top5(net: EfficientNetLite0, image: np.ndarray) -> set[int]:
    logits = net.logits(net.features(resize_for_cnn(image, size_px=224)[None]))[0]
    return {int(i) for i in np.argsort(-logits)[:5]}


def test_features_classify_natural_photos_into_their_imagenet_classes(net: EfficientNetLite0) -> None:
    data = pytest.importorskip("skimage.data")
    assert _top5(net, data.chelsea()) & CAT_CLASSES
    assert _top5(net, data.coffee()) & CUP_CLASSES


def test_features_are_batch_independent_and_non_negative(net: EfficientNetLite0) -> None:
    rng = np.random.default_rng(3)
    images = rng.integers(0, 256, (3, 64, 64, 3), dtype=np.uint8)
    batch = net.features(images)
    single = np.concatenate([net.features(images[i : i + 1]) for i in range(3)])
    assert batch.shape == (3, 1280)
    np.testing.assert_allclose(batch, single, rtol=1e-4, atol=1e-5)
    assert (batch >= 0).all()


def _reference_conv(x: np.ndarray, weight: np.ndarray, stride: int, *, depthwise: bool) -> np.ndarray:
    """Direct loops with TensorFlow SAME padding."""
    k = weight.shape[0]
    out_h, top, bottom = _same_padding(x.shape[1], k, stride)
    out_w, left, right = _same_padding(x.shape[2], k, stride)
    padded = np.pad(x, ((0, 0), (top, bottom), (left, right), (0, 0)))
    out = np.zeros((x.shape[0], out_h, out_w, weight.shape[-1]))
    for i in range(out_h):
        for j in range(out_w):
            patch = padded[:, i * stride : i * stride + k, j * stride : j * stride + k, :]
            if depthwise:
                out[:, i, j] = (patch * weight).sum(axis=(1, 2))
            else:
                out[:, i, j] = np.einsum("nijc,ijco->no", patch, weight)
    return out


@pytest.mark.parametrize(("kernel", "stride"), [(3, 1), (3, 2), (5, 1), (5, 2)])
def test_depthwise_matches_direct_convolution(kernel: int, stride: int) -> None:
    rng = np.random.default_rng(kernel * 10 + stride)
    x = rng.normal(size=(2, 9, 8, 4)).astype(np.float32)
    weight = rng.normal(size=(kernel, kernel, 4)).astype(np.float32)
    conv = _Conv(weight, np.zeros(4, np.float32), stride)
    np.testing.assert_allclose(_depthwise(x, conv), _reference_conv(x, weight, stride, depthwise=True), atol=1e-4)


def test_stem_matches_direct_convolution() -> None:
    rng = np.random.default_rng(5)
    x = rng.normal(size=(2, 10, 10, 3)).astype(np.float32)
    weight = rng.normal(size=(3, 3, 3, 6)).astype(np.float32)
    conv = _Conv(weight, np.zeros(6, np.float32), 2)
    np.testing.assert_allclose(_stem(x, conv), _reference_conv(x, weight, 2, depthwise=False), atol=1e-4)


def test_same_padding_follows_tensorflow() -> None:
    assert _same_padding(224, 3, 2) == (112, 0, 1)
    assert _same_padding(112, 5, 2) == (56, 1, 2)
    assert _same_padding(14, 5, 1) == (14, 2, 2)


def test_features_reject_non_rgb_batches(net: EfficientNetLite0) -> None:
    with pytest.raises(ObjectLabellingError, match="uint8 RGB"):
        net.features(np.zeros((1, 64, 64), np.uint8))
    with pytest.raises(ObjectLabellingError, match="below 32 px"):
        net.features(np.zeros((1, 16, 16, 3), np.uint8))


def test_load_rejects_a_state_dict_of_another_network() -> None:
    with pytest.raises(ObjectLabellingError, match="lack"):
        EfficientNetLite0.from_state_dict({"_conv_stem.weight": np.zeros((32, 3, 3, 3), np.float32)})
