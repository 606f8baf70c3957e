"""Interrupted writes: a dataset, run or bundle killed midway is never taken as complete.

Every writer goes through :func:`slipkit._files.atomic_dir` (a hidden sibling folder
renamed into place last). Two kinds of interruption are tested: an exception raised
inside the write (a full disk, a bug) and a real ``SIGKILL`` of a child process that
is blocked halfway through writing.
"""

from __future__ import annotations

import csv
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hydra import compose, initialize_config_dir
from omegaconf import DictConfig
from tests.runtime.helpers import linear_graph, manifest
from tests.strategies import make_dataset

import slipkit
from slipkit.data import io as data_io
from slipkit.data.commands import import_main
from slipkit.data.io import load_dataset, save_dataset
from slipkit.errors import DatasetError, SlipkitError
from slipkit.runtime import BundleError, load_bundle, write_bundle
from slipkit.runtime import bundle as bundle_module
from slipkit.sim.commands import simulate_main
from slipkit.train import commands as train_commands
from slipkit.train.runs import read_run

ROOT = Path(__file__).resolve().parents[2]


def _compose(config: str, overrides: list[str]) -> DictConfig:
    with initialize_config_dir(
        config_dir=str(slipkit.config_dir()), version_base="1.3"
    ):
        return compose(config_name=config, overrides=overrides)


def _fail_on_call(n: int, original: Any) -> Any:
    """A stand-in for a writer that works ``n - 1`` times, then fails like a full disk."""
    calls = [0]

    def writer(*args: Any, **kwargs: Any) -> Any:
        calls[0] += 1
        if calls[0] == n:
            raise OSError(28, "No space left on device (injected)")
        return original(*args, **kwargs)

    return writer


def _hidden(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir() if p.name.startswith("."))


# -- an exception midway -----------------------------------------------------------------
def test_simulate_failing_midway_leaves_no_dataset(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """`slipkit simulate` failing on its second table leaves neither the dataset nor a temporary folder."""
    monkeypatch.setattr(
        data_io, "_write_parquet", _fail_on_call(2, data_io._write_parquet)
    )
    out = tmp_path / "sim"
    cfg = _compose(
        "simulate",
        [
            "scene=fsr_probe_slide",
            "n_trials=1",
            f"out={out}",
            "progress=false",
            "summary=false",
            "scene.model.pass_s=1.0",
        ],
    )
    with pytest.raises(OSError, match="injected"):
        simulate_main(cfg)
    assert [] == list(tmp_path.iterdir())


def test_import_failing_midway_keeps_the_previous_dataset(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """`slipkit import ... overwrite=true` failing midway leaves the old dataset whole and loadable."""
    src = tmp_path / "src"
    src.mkdir()
    for name in ("a", "b"):
        with open(src / f"{name}.csv", "w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(["fx", "fz"])
            w.writerows([[0.1 * r, 2.0 * r] for r in range(5)])
    out = tmp_path / "ds"
    old = save_dataset(make_dataset(n_trials=2, n_frames=20), out)
    before = load_dataset(old).fingerprint()
    monkeypatch.setattr(
        data_io, "_write_parquet", _fail_on_call(2, data_io._write_parquet)
    )
    cfg = _compose(
        "import",
        [
            "source=csv",
            f"path={src}",
            f"out={out}",
            "overwrite=true",
            "source.sensor=fsr",
            "source.rate_hz=10",
            "source.units=N",
        ],
    )
    with pytest.raises(OSError, match="injected"):
        import_main(cfg)
    assert before == load_dataset(out).fingerprint()
    assert [] == _hidden(tmp_path)


def test_train_failing_before_run_json_leaves_no_run(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A training run dying after model.joblib but before run.json leaves no run folder to evaluate."""
    real = train_commands.write_json

    def write_json(path: Path, payload: Any) -> None:
        if Path(path).name == "run.json":
            raise OSError(28, "No space left on device (injected)")
        real(path, payload)

    monkeypatch.setattr(train_commands, "write_json", write_json)
    run = tmp_path / "runs" / "fsr"
    cfg = _compose(
        "train", ["experiment=fsr_roc", "dataset.n_trials=4", f"run_dir={run}"]
    )
    with pytest.raises(OSError, match="injected"):
        train_commands.train_main(cfg)
    assert [] == list(tmp_path.iterdir())  # not even the runs/ folder it created
    with pytest.raises(SlipkitError):
        read_run(run)


def test_bundle_write_failing_midway_leaves_nothing(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """write_bundle (what `slipkit export` calls) failing after model.onnx leaves no bundle folder."""

    def savez(*args: Any, **kwargs: Any) -> None:
        raise OSError(28, "No space left on device (injected)")

    monkeypatch.setattr(bundle_module.np, "savez", savez)
    with pytest.raises(OSError, match="injected"):
        write_bundle(
            tmp_path / "b",
            linear_graph(np.ones(12), 0.0),
            manifest(12),
            replay=(np.zeros((10, 3)), np.arange(10) / 100.0),
        )
    assert [] == list(tmp_path.iterdir())


# -- SIGKILL midway ------------------------------------------------------------------
CHILD = textwrap.dedent(
    """
    import sys, time
    sys.path.insert(0, {root!r})
    import numpy as np
    kind, target, marker = sys.argv[1:]

    def stall(original, at):
        calls = [0]
        def writer(*args, **kwargs):
            out = original(*args, **kwargs)
            calls[0] += 1
            if calls[0] == at:  # halfway: some files written, the rest pending
                open(marker, "w").close()
                time.sleep(120)
            return out
        return writer

    if kind in ("dataset", "overwrite"):
        from slipkit.data import io
        from tests.strategies import make_dataset
        io._write_parquet = stall(io._write_parquet, 2)
        io.save_dataset(make_dataset(n_trials=3, n_frames=20, seed=1), target,
                        overwrite=kind == "overwrite")
    else:
        from slipkit.runtime import bundle_write
        from tests.runtime.helpers import linear_graph, manifest
        # The replay's checksum is taken after model.onnx and replay.npz are written
        # and before manifest.json is.
        bundle_write.sha256_file = stall(bundle_write.sha256_file, 1)
        bundle_write.write_bundle(target, linear_graph(np.ones(12), 0.0), manifest(12),
                            replay=(np.zeros((10, 3)), np.arange(10) / 100.0))
    """
)


def _kill_midway(kind: str, target: Path) -> None:
    """Run a child writing ``target`` and SIGKILL it once it is blocked halfway."""
    marker = target.parent / f"{target.name}.halfway"
    script = target.parent / "child.py"
    script.write_text(CHILD.format(root=str(ROOT)))
    proc = subprocess.Popen(
        [sys.executable, str(script), kind, str(target), str(marker)],
        cwd=ROOT,
        stderr=subprocess.PIPE,
    )
    try:
        deadline = time.monotonic() + 120
        while not marker.exists():
            assert proc.poll() is None, (
                proc.stderr.read().decode()[-2000:] if proc.stderr else ""
            )
            assert time.monotonic() < deadline, (
                "the child never reached the halfway point"
            )
            time.sleep(0.02)
        os.kill(proc.pid, signal.SIGKILL)
    finally:
        proc.wait(timeout=30)
        if proc.stderr:
            proc.stderr.close()
    assert -signal.SIGKILL == proc.returncode
    marker.unlink()
    script.unlink()


def test_sigkill_while_saving_a_dataset_leaves_no_dataset(tmp_path: Path) -> None:
    """A process killed between two Parquet files leaves no dataset; its hidden leftover is refused too."""
    target = tmp_path / "ds"
    _kill_midway("dataset", target)
    assert not target.exists()
    with pytest.raises(DatasetError, match="not a folder"):
        load_dataset(target)
    (leftover,) = [tmp_path / name for name in _hidden(tmp_path)]
    assert leftover.name.startswith(".ds.tmp-")
    with pytest.raises(DatasetError, match=r"manifest\.json"):
        load_dataset(leftover)


def test_sigkill_while_overwriting_keeps_the_old_dataset(tmp_path: Path) -> None:
    """A process killed while replacing a dataset leaves the old one in place, unchanged."""
    target = save_dataset(make_dataset(n_trials=2, n_frames=20), tmp_path / "ds")
    before = load_dataset(target).fingerprint()
    _kill_midway("overwrite", target)
    assert before == load_dataset(target).fingerprint()


def test_sigkill_while_writing_a_bundle_leaves_no_bundle(tmp_path: Path) -> None:
    """A process killed after model.onnx and replay.npz but before manifest.json leaves no bundle."""
    target = tmp_path / "bundle"
    _kill_midway("bundle", target)
    assert not target.exists()
    with pytest.raises(BundleError):
        load_bundle(target)
    (leftover,) = [tmp_path / name for name in _hidden(tmp_path)]
    assert (leftover / "model.onnx").exists()
    with pytest.raises(BundleError, match=r"manifest\.json"):
        load_bundle(leftover)
