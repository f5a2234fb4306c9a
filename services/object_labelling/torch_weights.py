"""Read a PyTorch state dict into numpy arrays without executing pickled code.

PyTorch checkpoints are pickles. Unpickling one with :mod:`pickle` would run whatever callables it
names, so this reader uses a restricted unpickler that resolves only the handful of globals a plain
state dict needs (``collections.OrderedDict``, ``torch._utils._rebuild_tensor_v2`` and the typed
storage classes) to local stand-ins, and reads tensor storages itself with numpy. Both the legacy
format (``torch.save`` before 1.6: consecutive pickles followed by raw storages) and the zip
format (``archive/data.pkl`` plus ``archive/data/<key>`` entries) are understood.
"""

from __future__ import annotations

import collections
import hashlib
import io
import pickle
import re
import zipfile
from collections.abc import Callable
from pathlib import Path
from typing import Any, BinaryIO, NamedTuple

import numpy as np
import numpy.typing as npt

from services.object_labelling.errors import ObjectLabellingError

_LEGACY_MAGIC = 0x1950A86A20F9469CFC6C
_STORAGE_DTYPES: dict[str, np.dtype[Any]] = {
    "FloatStorage": np.dtype("<f4"),
    "DoubleStorage": np.dtype("<f8"),
    "HalfStorage": np.dtype("<f2"),
    "LongStorage": np.dtype("<i8"),
    "IntStorage": np.dtype("<i4"),
    "ShortStorage": np.dtype("<i2"),
    "CharStorage": np.dtype("i1"),
    "ByteStorage": np.dtype("u1"),
    "BoolStorage": np.dtype("?"),
}
_HASH_IN_NAME = re.compile(r"-([0-9a-f]{8,64})\.(?:pth|pt)$")


class _StorageType(NamedTuple):
    dtype: np.dtype[Any]


class _StorageRef(NamedTuple):
    key: str
    dtype: np.dtype[Any]
    numel: int


class _TensorRef(NamedTuple):
    storage: _StorageRef
    offset: int
    shape: tuple[int, ...]
    stride: tuple[int, ...]


def _rebuild_tensor_v2(
    storage: _StorageRef, offset: int, shape: tuple[int, ...], stride: tuple[int, ...], *_: object
) -> _TensorRef:
    return _TensorRef(storage, int(offset), tuple(shape), tuple(stride))


class _RestrictedUnpickler(pickle.Unpickler):
    """Resolves only state-dict globals; every other global is refused."""

    def find_class(self, module: str, name: str) -> Any:
        if (module, name) == ("collections", "OrderedDict"):
            return collections.OrderedDict
        if (module, name) == ("torch._utils", "_rebuild_tensor_v2"):
            return _rebuild_tensor_v2
        if module == "torch" and name in _STORAGE_DTYPES:
            return _StorageType(_STORAGE_DTYPES[name])
        raise ObjectLabellingError(f"checkpoint names the global {module}.{name}, which a state dict never needs")

    def persistent_load(self, pid: Any) -> _StorageRef:
        if not (isinstance(pid, tuple) and len(pid) >= 5 and pid[0] == "storage"):
            raise ObjectLabellingError(f"checkpoint has an unexpected persistent id {pid!r:.80}")
        storage_type, key, numel = pid[1], str(pid[2]), int(pid[4])
        if not isinstance(storage_type, _StorageType):
            raise ObjectLabellingError(f"checkpoint storage {key} has no known element type")
        return _StorageRef(key, storage_type.dtype, numel)


def _unpickle(stream: BinaryIO) -> Any:
    try:
        return _RestrictedUnpickler(stream).load()
    except ObjectLabellingError:
        raise
    except Exception as err:  # any malformed pickle: EOFError, UnpicklingError, TypeError, ...
        raise ObjectLabellingError(f"checkpoint pickle is corrupt: {err}") from err


def _materialise(state: Any, read_storage: Callable[[_StorageRef], npt.NDArray[Any]]) -> dict[str, npt.NDArray[Any]]:
    if not isinstance(state, dict):
        raise ObjectLabellingError(f"checkpoint holds a {type(state).__name__}, not a state dict")
    storages: dict[str, npt.NDArray[Any]] = {}
    tensors: dict[str, npt.NDArray[Any]] = {}
    for name, ref in state.items():
        if not isinstance(ref, _TensorRef):
            raise ObjectLabellingError(f"checkpoint entry {name!r} is not a tensor")
        if ref.storage.key not in storages:
            storages[ref.storage.key] = read_storage(ref.storage)
        flat = storages[ref.storage.key]
        itemsize = flat.dtype.itemsize
        extent = ref.offset + sum((n - 1) * s for n, s in zip(ref.shape, ref.stride, strict=True)) + 1
        if ref.offset < 0 or (all(ref.shape) and extent > flat.size):
            raise ObjectLabellingError(f"tensor {name!r} reaches past the end of its storage")
        tensors[str(name)] = np.lib.stride_tricks.as_strided(
            flat[ref.offset :], shape=ref.shape, strides=tuple(s * itemsize for s in ref.stride)
        ).copy()
    return tensors


def _load_legacy(raw: bytes) -> dict[str, npt.NDArray[Any]]:
    stream = io.BytesIO(raw)
    if _unpickle(stream) != _LEGACY_MAGIC:
        raise ObjectLabellingError("file is neither a zip nor a legacy PyTorch checkpoint (bad magic number)")
    _unpickle(stream)  # protocol version
    sys_info = _unpickle(stream)
    if not (isinstance(sys_info, dict) and sys_info.get("little_endian", False)):
        raise ObjectLabellingError("checkpoint was written on a big-endian machine; not supported")
    state = _unpickle(stream)
    keys = _unpickle(stream)
    if not (isinstance(state, dict) and isinstance(keys, list)):
        raise ObjectLabellingError("checkpoint state dict or storage key list is corrupt")
    dtypes = {ref.storage.key: ref.storage.dtype for ref in state.values() if isinstance(ref, _TensorRef)}
    # each storage follows in key order as an int64 element count and its raw little-endian data
    offsets: dict[str, tuple[int, int]] = {}
    position = stream.tell()
    for key in map(str, keys):
        if key not in dtypes:
            raise ObjectLabellingError(f"checkpoint storage {key} is not used by any tensor")
        if position + 8 > len(raw):
            raise ObjectLabellingError("checkpoint is truncated in its storage section")
        numel = int(np.frombuffer(raw, "<i8", 1, position)[0])
        offsets[key] = (position + 8, numel)
        position += 8 + numel * dtypes[key].itemsize
    if position > len(raw):
        raise ObjectLabellingError("checkpoint is truncated in its storage section")

    def read_storage(ref: _StorageRef) -> npt.NDArray[Any]:
        if ref.key not in offsets:
            raise ObjectLabellingError(f"checkpoint storage {ref.key} is missing")
        start, numel = offsets[ref.key]
        return np.frombuffer(raw, ref.dtype, numel, start)

    return _materialise(state, read_storage)


def _load_zip(path: Path) -> dict[str, npt.NDArray[Any]]:
    try:
        with zipfile.ZipFile(path) as archive:
            names = archive.namelist()
            pickles = [n for n in names if n.endswith("/data.pkl") or n == "data.pkl"]
            if len(pickles) != 1:
                raise ObjectLabellingError(f"zip checkpoint {path} has {len(pickles)} data.pkl entries")
            prefix = pickles[0][: -len("data.pkl")]
            state = _unpickle(io.BytesIO(archive.read(pickles[0])))

            def read_storage(ref: _StorageRef) -> npt.NDArray[Any]:
                entry = f"{prefix}data/{ref.key}"
                if entry not in names:
                    raise ObjectLabellingError(f"zip checkpoint {path} lacks storage entry {entry}")
                data = archive.read(entry)
                if len(data) < ref.numel * ref.dtype.itemsize:
                    raise ObjectLabellingError(f"zip checkpoint storage {entry} is truncated")
                return np.frombuffer(data, ref.dtype, ref.numel)

            return _materialise(state, read_storage)
    except zipfile.BadZipFile as err:
        raise ObjectLabellingError(f"zip checkpoint {path} is corrupt: {err}") from err


def verify_name_hash(path: Path) -> None:
    """Check that the hex digest prefix in ``path``'s name (``name-<sha256 prefix>.pth``) matches.

    Raises :class:`ObjectLabellingError` when the name carries no digest or it does not match.
    """
    match = _HASH_IN_NAME.search(path.name)
    if match is None:
        raise ObjectLabellingError(f"weights file name {path.name} carries no sha256 prefix")
    digest = hashlib.sha256(path.read_bytes()).hexdigest()
    if not digest.startswith(match.group(1)):
        raise ObjectLabellingError(
            f"weights file {path} has sha256 {digest[:16]}..., its name says {match.group(1)}: corrupt or replaced"
        )


def load_state_dict(path: str | Path, *, verify_hash: bool = True) -> dict[str, npt.NDArray[Any]]:
    """Tensors of a PyTorch state-dict checkpoint as numpy arrays, loaded without running pickled code.

    Parameters
    ----------
    path
        A ``.pth``/``.pt`` file written by ``torch.save(model.state_dict())``, legacy or zip format.
    verify_hash
        Check the sha256 prefix carried in the file name (torchvision/timm convention) first.

    Returns
    -------
    dict
        Parameter name to array (contiguous copy, dtype as stored, e.g. float32).

    Raises
    ------
    ObjectLabellingError
        Missing file, digest mismatch, a pickle naming any global outside a state dict, or a
        truncated/corrupt file.
    """
    path = Path(path)
    if not path.is_file():
        raise ObjectLabellingError(f"weights file {path} does not exist")
    if verify_hash:
        verify_name_hash(path)
    if zipfile.is_zipfile(path):
        return _load_zip(path)
    return _load_legacy(path.read_bytes())
