from __future__ import annotations

import io
import os
import pickle
import shutil
import sys
import types
import zipfile
from collections import OrderedDict
from pathlib import Path

import numpy as np
import pytest

from services.object_labelling import ObjectLabellingError, load_state_dict, verify_name_hash


def test_load_state_dict_reads_the_shipped_lite0_checkpoint(weights_path: Path) -> None:
    state = load_state_dict(weights_path)
    assert state["_conv_stem.weight"].shape == (32, 3, 3, 3)
    assert state["_fc.weight"].shape == (1000, 1280)
    assert state["_conv_stem.weight"].dtype == np.float32
    assert all(np.isfinite(v).all() for v in state.values())


def test_load_state_dict_rejects_a_file_whose_digest_disagrees_with_its_name(
    weights_path: Path, tmp_path: Path
) -> None:
    copy = tmp_path / weights_path.name
    shutil.copy(weights_path, copy)
    with copy.open("r+b") as stream:
        stream.seek(100_000)
        byte = stream.read(1)
        stream.seek(100_000)
        stream.write(bytes([byte[0] ^ 0xFF]))
    with pytest.raises(ObjectLabellingError, match="sha256"):
        load_state_dict(copy)


def test_verify_name_hash_needs_a_digest_in_the_name(tmp_path: Path) -> None:
    path = tmp_path / "weights.pth"
    path.write_bytes(b"x")
    with pytest.raises(ObjectLabellingError, match="carries no sha256"):
        verify_name_hash(path)


def test_load_state_dict_reports_a_truncated_checkpoint(weights_path: Path, tmp_path: Path) -> None:
    cut = tmp_path / "cut.pth"
    cut.write_bytes(weights_path.read_bytes()[:1_000_000])
    with pytest.raises(ObjectLabellingError, match=r"truncated|corrupt"):
        load_state_dict(cut, verify_hash=False)


def test_load_state_dict_reports_a_missing_file(tmp_path: Path) -> None:
    with pytest.raises(ObjectLabellingError, match="does not exist"):
        load_state_dict(tmp_path / "efficientnet-lite0-00000000.pth")


class _Exploit:
    def __reduce__(self) -> tuple[object, tuple[str]]:
        return (os.system, ("echo pwned",))


def test_load_state_dict_never_runs_code_named_in_the_pickle(tmp_path: Path) -> None:
    path = tmp_path / "evil.pth"
    with zipfile.ZipFile(path, "w") as archive:
        archive.writestr("archive/data.pkl", pickle.dumps(OrderedDict(x=_Exploit()), protocol=2))
    with pytest.raises(ObjectLabellingError, match="names the global"):
        load_state_dict(path, verify_hash=False)


def _fake_torch(monkeypatch: pytest.MonkeyPatch) -> tuple[type, object]:
    """Stand-ins so that pickle writes the same globals torch.save would."""
    torch = types.ModuleType("torch")
    utils = types.ModuleType("torch._utils")

    class FloatStorage:
        pass

    def _rebuild_tensor_v2(*args: object) -> None:
        raise AssertionError("never called")

    FloatStorage.__module__, FloatStorage.__qualname__ = "torch", "FloatStorage"
    _rebuild_tensor_v2.__module__, _rebuild_tensor_v2.__qualname__ = "torch._utils", "_rebuild_tensor_v2"
    torch.FloatStorage = FloatStorage  # type: ignore[attr-defined]
    utils._rebuild_tensor_v2 = _rebuild_tensor_v2  # type: ignore[attr-defined]
    monkeypatch.setitem(sys.modules, "torch", torch)
    monkeypatch.setitem(sys.modules, "torch._utils", utils)
    return FloatStorage, _rebuild_tensor_v2


def test_load_state_dict_reads_zip_checkpoints_with_strided_tensors(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    storage_type, rebuild = _fake_torch(monkeypatch)
    flat = np.arange(12, dtype="<f4")

    class Tensor:
        def __init__(self, offset: int, shape: tuple[int, ...], stride: tuple[int, ...]) -> None:
            self.args: tuple[object, ...] = (
                ("storage", storage_type, "0", "cpu", 12),
                offset,
                shape,
                stride,
                False,
                OrderedDict(),
            )

        def __reduce__(self) -> tuple[object, tuple[object, ...]]:
            return (rebuild, self.args)

    class Pickler(pickle.Pickler):
        def persistent_id(self, obj: object) -> object:
            return obj if isinstance(obj, tuple) and obj and obj[0] == "storage" else None

    buffer = io.BytesIO()
    Pickler(buffer, protocol=2).dump(OrderedDict(a=Tensor(0, (3, 4), (4, 1)), t=Tensor(1, (2, 2), (1, 4))))
    path = tmp_path / "tiny.pt"
    with zipfile.ZipFile(path, "w") as archive:
        archive.writestr("tiny/data.pkl", buffer.getvalue())
        archive.writestr("tiny/data/0", flat.tobytes())
    state = load_state_dict(path, verify_hash=False)
    np.testing.assert_array_equal(state["a"], flat.reshape(3, 4))
    np.testing.assert_array_equal(state["t"], [[1, 5], [2, 6]])
