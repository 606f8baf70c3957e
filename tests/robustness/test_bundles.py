"""Bundles: truncated graphs and pickles are refused at load, and loading never runs code.

The field-by-field checks (missing fields, wrong types, a newer schema, an input
that does not match the graph, tampered files) are in ``tests/runtime/test_bundle.py``.
"""

from __future__ import annotations

import pickle
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from tests.runtime.helpers import LinearCase

from slipkit._files import sha256_file
from slipkit.runtime import (
    BundleError,
    FrameError,
    ReplaySource,
    StreamLoop,
    load_bundle,
    load_replay,
)


@pytest.fixture
def case(tmp_path: Path) -> LinearCase:
    return LinearCase(tmp_path)


def _resign(case: LinearCase, name: str) -> None:
    """Update the manifest's checksum of ``name`` (and its digest), as an attacker or a
    broken tool might."""
    sha = sha256_file(case.path / name)
    case.edit_manifest(lambda man: man["files"].__setitem__(name, sha))


@pytest.mark.parametrize("keep", [0.5, 0.1, 0.0])
def test_truncated_onnx_is_refused_by_its_checksum(
    case: LinearCase, keep: float
) -> None:
    """A model.onnx cut short is refused before onnxruntime reads it, naming the file and checksum."""
    model = case.path / "model.onnx"
    data = model.read_bytes()
    model.write_bytes(data[: int(len(data) * keep)])
    with pytest.raises(
        BundleError, match="the file changed after the bundle was written"
    ) as info:
        load_bundle(case.path)
    assert str(model) == info.value.file


@pytest.mark.parametrize("keep", [0.5, 0.1, 0.0])
def test_truncated_onnx_with_a_matching_checksum_is_refused_by_onnxruntime(
    case: LinearCase, keep: float
) -> None:
    """Even with its checksum re-signed, a truncated graph is a BundleError naming model.onnx, not a crash."""
    model = case.path / "model.onnx"
    data = model.read_bytes()
    model.write_bytes(data[: int(len(data) * keep)])
    _resign(case, "model.onnx")
    with pytest.raises(BundleError, match="onnxruntime refused it") as info:
        load_bundle(case.path)
    assert str(model) == info.value.file


def test_loading_and_running_a_bundle_never_unpickles(
    case: LinearCase, monkeypatch: pytest.MonkeyPatch
) -> None:
    """load_bundle, the replay and the loop run with every pickle entry point disabled."""

    def refuse(*args: Any, **kwargs: Any) -> Any:
        raise AssertionError("a bundle load tried to unpickle")

    for name in ("load", "loads", "Unpickler"):
        monkeypatch.setattr(pickle, name, refuse)
    bundle = load_bundle(case.path)
    assert bundle.replay_path is not None
    frames, times = load_replay(bundle.replay_path, (3,), 100.0)
    result = StreamLoop(bundle).run(ReplaySource(frames, times))
    assert len(frames) - case.window + 1 == len(result.slip)


def test_replay_that_needs_pickle_is_refused_even_when_signed(case: LinearCase) -> None:
    """A replay.npz holding an object array (only loadable by unpickling) is refused by name."""
    obj = np.empty(4, dtype=object)
    obj[:] = [{"a": 1}] * 4
    np.savez(case.path / "replay.npz", frames=obj, timestamps=np.arange(4.0))
    _resign(case, "replay.npz")
    bundle = load_bundle(case.path)  # the checksum matches: the content check follows
    assert bundle.replay_path is not None
    with pytest.raises(FrameError, match="without pickles"):
        load_replay(bundle.replay_path, (3,), 100.0)
