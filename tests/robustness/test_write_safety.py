"""Writes that could lose data (issue 12): no command replaces or deletes what it did not write.

The rules live in :mod:`slipkit._files` (``check_out_path``, ``atomic_dir``): an output
never is, holds or sits inside one of the command's inputs, never sits inside another
slipkit folder, replaces only a folder of its own kind (with ``overwrite``), and an
interrupted overwrite never leaves the name empty. Commands run through the in-process
CLI (``slipkit.cli.main``), as a user types them.
"""

from __future__ import annotations

import csv
import logging
import os
import shutil
import signal
import stat
import subprocess
import sys
import textwrap
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from tests.runtime.helpers import linear_graph, manifest
from tests.strategies import make_dataset

from slipkit import _files
from slipkit._files import atomic_dir, atomic_write_text, folder_kind
from slipkit.cli import main
from slipkit.data.io import load_dataset, save_dataset
from slipkit.errors import SlipkitError
from slipkit.runtime import load_bundle, write_bundle
from slipkit.train.runs import read_run

ROOT = Path(__file__).resolve().parents[2]


# -- helpers ------------------------------------------------------------------------------
def _cli(args: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str]:
    """Run ``slipkit <args>`` in process; (exit status, stderr)."""
    capsys.readouterr()
    try:
        main(args)
        code = 0
    except SystemExit as exc:
        code = int(exc.code or 0)
    return code, capsys.readouterr().err


def _snapshot(root: Path) -> dict[str, Any]:
    """Every path under ``root`` -> its bytes (files), its target (links), None (folders),
    or its type and inode (a FIFO, socket or device: never opened)."""
    out: dict[str, Any] = {}
    for here, dirs, files in os.walk(root):
        for name in dirs + files:
            p = Path(here) / name
            rel = p.relative_to(root).as_posix()
            st = p.lstat()
            out[rel] = (
                ("link", os.readlink(p))
                if stat.S_ISLNK(st.st_mode)
                else None
                if stat.S_ISDIR(st.st_mode)
                else p.read_bytes()
                if stat.S_ISREG(st.st_mode)
                else ("special", stat.S_IFMT(st.st_mode), st.st_ino)
            )
    return out


def _hidden(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir() if p.name.startswith("."))


def _docs(folder: Path) -> Path:
    """A lab's folder of documents: what must never be replaced."""
    folder.mkdir(parents=True)
    (folder / "notes.txt").write_text("months of recordings: do not lose\n")
    (folder / "sub").mkdir()
    (folder / "sub" / "data.bin").write_bytes(bytes(range(256)))
    return folder


def _csv_source(folder: Path) -> Path:
    folder.mkdir(parents=True)
    with open(folder / "a.csv", "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["fx", "fz"])
        w.writerows([[0.1 * r, 2.0 * r] for r in range(5)])
    return folder


CSV_OPTS = ["source=csv", "source.sensor=fsr", "source.rate_hz=10", "source.units=N"]
OVER = ["overwrite=true"]
SIM_OPTS = ["scene=fsr_probe_slide", "n_trials=1", "progress=false", "summary=false"]


@pytest.fixture(scope="module")
def pristine(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """A simulated FSR dataset, a run trained on it and a small bundle, made once."""
    root = tmp_path_factory.mktemp("pristine")
    sim = root / "sim"
    main(["simulate", *SIM_OPTS, "n_trials=4", f"out={sim}"])
    run = root / "run"
    main(["train", "experiment=fsr_roc", f"dataset.path={sim}", f"run_dir={run}"])
    bundle = write_bundle(
        root / "bundle",
        linear_graph(np.ones(12), 0.0),
        manifest(12),
        replay=(np.zeros((10, 3)), np.arange(10) / 100.0),
    )
    return {"sim": sim, "run": run, "bundle": bundle}


@pytest.fixture
def lab(tmp_path: Path, pristine: dict[str, Path]) -> dict[str, Path]:
    """Copies of the pristine folders under ``tmp_path/lab`` beside a folder of documents."""
    base = tmp_path / "lab"
    base.mkdir()
    out = {k: Path(shutil.copytree(v, base / k)) for k, v in pristine.items()}
    out["docs"] = _docs(base / "docs")
    return out


# -- 1. evaluate's name ------------------------------------------------------------------
@pytest.mark.parametrize(
    "name",
    ["<docs>", "../../..", "..", ".", "", ".hidden", "a/b", "a\\b", "../evaluations2"],
)
def test_evaluate_refuses_a_name_that_is_not_plain(
    name: str, lab: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """`slipkit evaluate name=<abs path | .. | hidden | empty | a/b>` exits 2 naming `name` and changes nothing."""
    name = str(lab["docs"]) if name == "<docs>" else name
    before = _snapshot(tmp_path)
    code, err = _cli(
        ["evaluate", f"run={lab['run']}", f"dataset={lab['sim']}", f"name={name}"],
        capsys,
    )
    assert (2, True) == (code, "error: name=" in err)
    assert before == _snapshot(tmp_path)


def test_evaluate_refuses_a_name_linked_outside_evaluations(
    lab: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """An `evaluations/<name>` that is a symlink to a folder elsewhere is refused, the folder kept."""
    (lab["run"] / "evaluations").mkdir(exist_ok=True)
    (lab["run"] / "evaluations" / "holdout").symlink_to(lab["docs"])
    before = _snapshot(tmp_path)
    code, err = _cli(
        ["evaluate", f"run={lab['run']}", f"dataset={lab['sim']}", "name=holdout"],
        capsys,
    )
    assert (2, True) == (code, "outside" in err)
    assert before == _snapshot(tmp_path)


def test_evaluate_refuses_to_replace_a_folder_that_is_not_an_evaluation(
    lab: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A user's own folder under `<run>/evaluations/` is not replaced by `slipkit evaluate`."""
    _docs(lab["run"] / "evaluations" / "notes")
    before = _snapshot(tmp_path)
    code, err = _cli(
        ["evaluate", f"run={lab['run']}", f"dataset={lab['sim']}", "name=notes"],
        capsys,
    )
    assert (2, True) == (code, "is not a slipkit evaluation" in err)
    assert before == _snapshot(tmp_path)


def test_reevaluating_under_the_same_name_replaces_that_evaluation(
    lab: dict[str, Path], capsys: pytest.CaptureFixture[str]
) -> None:
    """Evaluating twice under one name replaces the evaluation folder and leaves nothing hidden."""
    args = ["evaluate", f"run={lab['run']}", f"dataset={lab['sim']}", "name=holdout"]
    target = lab["run"] / "evaluations" / "holdout"
    assert 0 == _cli(args, capsys)[0]
    (target / "metrics.json").write_text('{"run": "x", "dataset": {}}')
    assert 0 == _cli(args, capsys)[0]
    assert ("evaluation", True) == (
        folder_kind(target),
        str(lab["sim"]) in (target / "metrics.json").read_text(),
    )
    assert [] == _hidden(target.parent)


# -- 2. overwrite replaces only its own kind; never an input ------------------------------
def test_import_overwrite_refuses_a_folder_of_documents(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """`slipkit import ... out=<documents> overwrite=true` exits 2 and keeps every document."""
    src, docs = _csv_source(tmp_path / "csv"), _docs(tmp_path / "docs")
    before = _snapshot(tmp_path)
    code, err = _cli(
        ["import", *CSV_OPTS, f"path={src}", f"out={docs}", "overwrite=true"], capsys
    )
    expected = (
        f"out={docs}: exists and is not a slipkit dataset; refusing to replace it"
    )
    assert (2, True) == (code, expected in err)
    assert before == _snapshot(tmp_path)


def test_simulate_overwrite_refuses_a_plain_file(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """`slipkit simulate out=<a file> overwrite=true` exits 2 and keeps the file."""
    path = tmp_path / "thesis.pdf"
    path.write_bytes(b"%PDF-1.7 not a dataset")
    code, err = _cli(["simulate", *SIM_OPTS, f"out={path}", "overwrite=true"], capsys)
    assert (2, True) == (
        code,
        f"out={path}: exists and is not a slipkit dataset" in err,
    )
    assert b"%PDF-1.7 not a dataset" == path.read_bytes()


@pytest.mark.parametrize(
    ("path", "out", "relation"),
    [
        ("csv", "csv", "is the input path="),
        ("csv", "csv/ds", "is inside the input path="),
        ("csv/inner", "csv", "contains the input path="),
    ],
)
def test_import_refuses_an_out_that_is_in_or_around_its_input(
    path: str,
    out: str,
    relation: str,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    """`slipkit import path=X out=X` (or inside X, or around X) exits 2 and the CSV files stay."""
    _csv_source(tmp_path / path)
    before = _snapshot(tmp_path)
    code, err = _cli(
        [
            "import",
            *CSV_OPTS,
            f"path={tmp_path / path}",
            f"out={tmp_path / out}",
            "overwrite=true",
        ],
        capsys,
    )
    assert (2, True) == (code, f"out={tmp_path / out}: {relation}" in err)
    assert before == _snapshot(tmp_path)


def test_train_refuses_a_run_dir_that_is_its_own_dataset(
    lab: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """`slipkit train dataset.path=D run_dir=D overwrite=true` exits 2 and the dataset stays loadable."""
    sim = lab["sim"]
    before = _snapshot(tmp_path)
    code, err = _cli(
        [
            "train",
            "experiment=fsr_roc",
            f"dataset.path={sim}",
            f"run_dir={sim}",
            "overwrite=true",
        ],
        capsys,
    )
    assert (2, True) == (code, f"run_dir={sim}: is the input dataset.path=" in err)
    assert before == _snapshot(tmp_path)


@pytest.mark.parametrize("where", ["docs", "run/bundle", "sim/bundle"])
def test_export_refuses_a_folder_that_is_not_a_bundle_or_lies_in_its_inputs(
    where: str,
    lab: dict[str, Path],
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    """`slipkit export out=<documents | inside the run | inside its data> overwrite=true` exits 2 before any work."""
    out = tmp_path / "lab" / where
    before = _snapshot(tmp_path)
    code, err = _cli(
        ["export", f"run={lab['run']}", f"out={out}", "overwrite=true"], capsys
    )
    assert (2, True) == (code, f"error: out={out}: " in err)
    assert before == _snapshot(tmp_path)


def test_compare_refuses_an_out_inside_its_dataset(
    lab: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """`slipkit compare comparison.dataset.path=D out=D/cmp` exits 2 before training anything."""
    out = lab["sim"] / "cmp"
    before = _snapshot(tmp_path)
    code, err = _cli(
        [
            "compare",
            "comparison=fsr",
            f"comparison.dataset.path={lab['sim']}",
            f"out={out}",
            "progress=false",
        ],
        capsys,
    )
    assert (2, True) == (code, f"out={out}: is inside the input" in err)
    assert before == _snapshot(tmp_path)


def test_demo_refuses_to_rewrite_a_folder_that_is_not_a_demo(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """`slipkit demo out=<documents>` (overwrite defaults to true) exits 2 and writes nothing."""
    docs = _docs(tmp_path / "docs")
    before = _snapshot(tmp_path)
    code, err = _cli(["demo", f"out={docs}", "quick=true", "progress=false"], capsys)
    assert (2, True) == (code, f"out={docs}: exists and is not a slipkit demo" in err)
    assert before == _snapshot(tmp_path)


def test_a_demo_output_may_be_rewritten_but_not_with_foreign_files(
    tmp_path: Path,
) -> None:
    """An earlier demo's output (data, compare, exports, closedloop, report.md) is accepted for overwrite; one extra file makes it foreign."""
    from slipkit import demo

    out = tmp_path / "demo"
    for sub in (demo.DATA, demo.COMPARE, demo.EXPORTS, demo.CLOSEDLOOP):
        (out / sub).mkdir(parents=True)
    (out / demo.CLOSEDLOOP / "fsr.log").write_text("closed loop fsr\n")
    (out / demo.REPORT).write_text("# slipkit demo: which detector to deploy\n")
    accepted = _files.check_out_path(out, layout=demo.LAYOUT, overwrite=True)
    (out / "thesis.tex").write_text("mine\n")
    with pytest.raises(SlipkitError, match="is not a slipkit demo"):
        _files.check_out_path(out, layout=demo.LAYOUT, overwrite=True)
    assert out == accepted


def test_the_demo_layout_names_every_entry_the_demo_writes() -> None:
    """The demo-folder check knows closedloop/ beside data/, compare/, exports/ and report.md."""
    from slipkit.demo import LAYOUT

    assert {"data", "compare", "exports", "closedloop", "report.md"} == set(
        LAYOUT.entries
    )


def test_a_folder_of_demo_names_with_other_content_is_not_a_demo(
    tmp_path: Path,
) -> None:
    """A `report.md` of the user's own, or a file named `data`, is not a demo output."""
    from slipkit.demo import LAYOUT

    (tmp_path / "mine" / "data").mkdir(parents=True)
    (tmp_path / "mine" / "report.md").write_text("# My thesis\n")
    (tmp_path / "file-data").mkdir()
    (tmp_path / "file-data" / "data").write_text("a file named like a demo folder\n")
    assert (False, False) == (
        LAYOUT.holds(tmp_path / "mine"),
        LAYOUT.holds(tmp_path / "file-data"),
    )


def test_a_closedloop_output_is_replaced_only_when_it_is_one(tmp_path: Path) -> None:
    """A folder as `slipkit closedloop` writes it may be overwritten (the demo's second run does); with a report of another title it may not."""
    out = tmp_path / "cl"
    out.mkdir()
    (out / "results.csv").write_text("detector\n")
    (out / "summary.csv").write_text("detector\n")
    (out / "report.md").write_text("# Closed loop: fsr\n")
    accepted = _files.check_out_path(out, kind="closedloop", overwrite=True)
    (out / "report.md").write_text("# My notes\n")
    with pytest.raises(SlipkitError, match="is not a slipkit closedloop"):
        _files.check_out_path(out, kind="closedloop", overwrite=True)
    assert out == accepted


@pytest.mark.slow
def test_demo_rewrites_its_own_output(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """`slipkit demo` run twice into one out (overwrite defaults to true) rewrites its own folders, the closed loop included."""
    from slipkit.demo import LAYOUT

    args = [
        "demo",
        f"out={tmp_path / 'demo'}",
        f"data_root={tmp_path / 'no-real-data'}",
        "quick=true",
        "progress=false",
        "~comparisons",
        "+comparisons={fsr: []}",
        "quick_seeds=[0]",
    ]
    runs = [_cli(args, capsys) for _ in range(2)]
    assert ([0, 0], [False, False], sorted(LAYOUT.entries)) == (
        [code for code, _ in runs],
        ["skipped" in err for _, err in runs],
        sorted(p.name for p in (tmp_path / "demo").iterdir()),
    )


def test_overwrite_replaces_a_folder_of_the_same_kind(tmp_path: Path) -> None:
    """A dataset replaces a dataset and a bundle a bundle; an empty folder may be filled."""
    ds = save_dataset(make_dataset(n_trials=2, n_frames=20), tmp_path / "ds")
    save_dataset(make_dataset(n_trials=2, n_frames=20, seed=3), ds, overwrite=True)
    graph, man = linear_graph(np.ones(12), 0.0), manifest(12)
    bundle = write_bundle(tmp_path / "b", graph, man)
    write_bundle(bundle, graph, {**man, "name": "again"}, overwrite=True)
    (tmp_path / "empty").mkdir()
    save_dataset(
        make_dataset(n_trials=2, n_frames=20), tmp_path / "empty", overwrite=True
    )
    assert (
        make_dataset(n_trials=2, n_frames=20, seed=3).fingerprint(),
        "again",
        "dataset",
        ["b", "ds", "empty"],
    ) == (
        load_dataset(ds).fingerprint(),
        load_bundle(bundle).manifest.name,
        folder_kind(tmp_path / "empty"),
        sorted(p.name for p in tmp_path.iterdir()),
    )


@pytest.mark.parametrize(
    ("kind", "other"), [("dataset", "bundle"), ("bundle", "sim"), ("run", "sim")]
)
def test_overwrite_never_crosses_kinds(
    kind: str, other: str, lab: dict[str, Path], tmp_path: Path
) -> None:
    """atomic_dir(kind=K, overwrite=True) refuses a slipkit folder of another kind."""
    target = lab[other]
    before = _snapshot(tmp_path)
    with (
        pytest.raises(SlipkitError, match=f"is not a slipkit {kind}; refusing"),
        atomic_dir(target, overwrite=True, kind=kind),
    ):
        pass
    assert before == _snapshot(tmp_path)


def test_overwrite_without_a_kind_replaces_nothing(tmp_path: Path) -> None:
    """atomic_dir(overwrite=True) without a kind refuses any non-empty folder."""
    ds = save_dataset(make_dataset(n_trials=2, n_frames=20), tmp_path / "ds")
    before = _snapshot(tmp_path)
    with (
        pytest.raises(SlipkitError, match="refusing to replace it"),
        atomic_dir(ds, overwrite=True),
    ):
        pass
    assert before == _snapshot(tmp_path)


def test_a_failed_write_removes_the_parents_it_created(tmp_path: Path) -> None:
    """A write that fails leaves none of the empty parents it made (runs/<name>/), and keeps any that hold something."""
    (tmp_path / "runs").mkdir()
    (tmp_path / "runs" / "keep.txt").write_text("lab notes")
    before = _snapshot(tmp_path)
    with (
        pytest.raises(RuntimeError, match="training failed"),
        atomic_dir(tmp_path / "runs" / "name" / "2026-01-01", kind="run"),
    ):
        raise RuntimeError("training failed")
    assert before == _snapshot(tmp_path)
    assert ["keep.txt"] == sorted(p.name for p in (tmp_path / "runs").iterdir())


def test_a_symlinked_out_is_refused(tmp_path: Path) -> None:
    """An `out` that is a symbolic link (even to a dataset) is not replaced."""
    ds = save_dataset(make_dataset(n_trials=2, n_frames=20), tmp_path / "ds")
    (tmp_path / "link").symlink_to(ds)
    before = _snapshot(tmp_path)
    with pytest.raises(SlipkitError, match="symbolic link"):
        save_dataset(
            make_dataset(n_trials=2, n_frames=20), tmp_path / "link", overwrite=True
        )
    assert before == _snapshot(tmp_path)


def test_format_constants_match_their_modules() -> None:
    """The formats _files recognises are the ones the dataset, run and bundle modules write."""
    from slipkit.data.dataset import FORMAT as DATASET
    from slipkit.runtime.bundle import FORMAT as BUNDLE
    from slipkit.train.runs import RUN_FORMAT

    assert (DATASET, RUN_FORMAT, BUNDLE) == (
        _files.DATASET_FORMAT,
        _files.RUN_FORMAT,
        _files.BUNDLE_FORMAT,
    )


# -- 3. an interrupted overwrite never leaves the name empty -------------------------------
def _replace_failing_on(n: int, exc: BaseException, *, after: bool = False) -> Any:
    """``os.replace`` that raises ``exc`` on its ``n``-th call (before or after renaming)."""
    real = os.replace
    calls = [0]

    def replace(src: Any, dst: Any) -> None:
        calls[0] += 1
        if calls[0] == n and not after:
            raise exc
        real(src, dst)
        if calls[0] == n:
            raise exc

    return replace


@pytest.mark.parametrize(
    "exc", [OSError(5, "Input/output error (injected)"), KeyboardInterrupt()]
)
def test_failure_between_the_two_renames_restores_the_old_dataset(
    exc: BaseException, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """An error or Ctrl-C between moving the old dataset aside and renaming the new one puts the old one back."""
    ds = save_dataset(make_dataset(n_trials=2, n_frames=20), tmp_path / "ds")
    before = load_dataset(ds).fingerprint()
    monkeypatch.setattr(_files.os, "replace", _replace_failing_on(2, exc))
    with pytest.raises(type(exc)):
        save_dataset(make_dataset(n_trials=2, n_frames=20, seed=4), ds, overwrite=True)
    monkeypatch.undo()
    assert (before, ["ds"]) == (
        load_dataset(ds).fingerprint(),
        sorted(p.name for p in tmp_path.iterdir()),
    )


def test_interrupt_right_after_the_second_rename_keeps_the_new_dataset(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Ctrl-C landing just after the new dataset is in place keeps it and leaves no hidden copy."""
    ds = save_dataset(make_dataset(n_trials=2, n_frames=20), tmp_path / "ds")
    new = make_dataset(n_trials=2, n_frames=20, seed=4)
    monkeypatch.setattr(
        _files.os, "replace", _replace_failing_on(2, KeyboardInterrupt(), after=True)
    )
    with pytest.raises(KeyboardInterrupt):
        save_dataset(new, ds, overwrite=True)
    monkeypatch.undo()
    assert (new.fingerprint(), ["ds"]) == (
        load_dataset(ds).fingerprint(),
        sorted(p.name for p in tmp_path.iterdir()),
    )


def _leave_old_copy(target: Path) -> Path:
    """What a kill between the two renames leaves: the target moved into `.<name>.old-*`."""
    old = target.parent / f".{target.name}.old-k1ll3d"
    old.mkdir()
    os.replace(target, old / target.name)
    return old


@pytest.mark.parametrize("reader", ["load_dataset", "read_run", "load_bundle", "write"])
def test_a_copy_left_aside_is_restored_on_the_next_start(
    reader: str,
    lab: dict[str, Path],
    caplog: pytest.LogCaptureFixture,
) -> None:
    """A `.<name>.old-*` whose target is missing is renamed back (and logged) by the next read or write."""
    key = {"load_dataset": "sim", "read_run": "run", "load_bundle": "bundle"}.get(
        reader, "sim"
    )
    target = lab[key]
    before = _snapshot(target)
    old = _leave_old_copy(target)
    with caplog.at_level(logging.WARNING, logger="slipkit.files"):
        if reader == "write":
            with pytest.raises(SlipkitError, match="already exists"):
                save_dataset(make_dataset(n_trials=2, n_frames=20), target)
        else:
            {"load_dataset": load_dataset, "read_run": read_run}.get(
                reader, load_bundle
            )(target)
    assert (before, False, True) == (
        _snapshot(target),
        old.exists(),
        f"restored from {old}" in caplog.text,
    )


def test_a_leftover_temporary_folder_is_reported(
    lab: dict[str, Path], caplog: pytest.LogCaptureFixture
) -> None:
    """A `.<name>.tmp-*` beside a dataset is named in a warning when the dataset is read."""
    leftover = lab["sim"].parent / ".sim.tmp-k1ll3d"
    leftover.mkdir()
    with caplog.at_level(logging.WARNING, logger="slipkit.files"):
        load_dataset(lab["sim"])
    assert (True, True) == (str(leftover) in caplog.text, leftover.exists())


def test_a_stale_old_copy_beside_a_complete_target_is_reported(
    lab: dict[str, Path], caplog: pytest.LogCaptureFixture
) -> None:
    """An `.<name>.old-*` left while the new dataset is in place is reported, never deleted."""
    stale = lab["sim"].parent / ".sim.old-k1ll3d"
    shutil.copytree(lab["sim"], stale / "sim")
    with caplog.at_level(logging.WARNING, logger="slipkit.files"):
        save_dataset(make_dataset(n_trials=2, n_frames=20), lab["sim"], overwrite=True)
    assert (True, True) == (str(stale) in caplog.text, (stale / "sim").is_dir())


CHILD = textwrap.dedent(
    """
    import os, sys, time
    sys.path.insert(0, {root!r})
    from slipkit import _files
    from slipkit.data import io
    from tests.strategies import make_dataset
    target, marker = sys.argv[1:]
    real, calls = os.replace, [0]

    def replace(src, dst):
        calls[0] += 1
        real(src, dst)
        if calls[0] == 1:  # the old dataset is aside, the new one not yet renamed
            open(marker, "w").close()
            time.sleep(120)

    _files.os.replace = replace
    io.save_dataset(make_dataset(n_trials=3, n_frames=20, seed=1), target, overwrite=True)
    """
)


def test_sigkill_between_the_two_renames_loses_nothing(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    """A process killed between the two renames of an overwrite: the next read restores the old dataset."""
    target = save_dataset(make_dataset(n_trials=2, n_frames=20), tmp_path / "ds")
    before = load_dataset(target).fingerprint()
    marker, script = tmp_path / "halfway", tmp_path / "child.py"
    script.write_text(CHILD.format(root=str(ROOT)))
    proc = subprocess.Popen(
        [sys.executable, str(script), str(target), str(marker)],
        cwd=ROOT,
        stderr=subprocess.PIPE,
    )
    try:
        deadline = time.monotonic() + 120
        while not marker.exists():
            assert proc.poll() is None, proc.stderr.read().decode()[-2000:]  # type: ignore[union-attr]
            assert time.monotonic() < deadline, "the child never reached the swap"
            time.sleep(0.02)
        os.kill(proc.pid, signal.SIGKILL)
    finally:
        proc.wait(timeout=30)
        proc.stderr.close()  # type: ignore[union-attr]
    assert (-signal.SIGKILL, False) == (proc.returncode, target.exists())
    with caplog.at_level(logging.WARNING, logger="slipkit.files"):
        after = load_dataset(target).fingerprint()
    (tmp_left,) = [p for p in _hidden(tmp_path) if p.startswith(".ds.tmp-")]
    assert (before, True, True) == (
        after,
        "restored from" in caplog.text,
        tmp_left in caplog.text,
    )


# -- 4. never inside another slipkit folder -----------------------------------------------
@pytest.mark.parametrize("inside", ["sim/streams/x.parquet", "run/data", "bundle/ds"])
def test_simulate_refuses_an_out_inside_a_slipkit_folder(
    inside: str,
    lab: dict[str, Path],
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    """`slipkit simulate out=<dataset>/streams/x.parquet` (or inside a run or bundle) exits 2; the folder stays intact."""
    out = tmp_path / "lab" / inside
    before = _snapshot(tmp_path)
    code, err = _cli(["simulate", *SIM_OPTS, f"out={out}"], capsys)
    kind = {"sim": "dataset", "run": "run", "bundle": "bundle"}[inside.split("/")[0]]
    assert (2, True) == (code, f"out={out}: is inside the slipkit {kind}" in err)
    assert before == _snapshot(tmp_path)


def test_writers_refuse_a_target_inside_a_slipkit_folder(lab: dict[str, Path]) -> None:
    """save_dataset and write_bundle themselves refuse a folder inside a dataset."""
    before = _snapshot(lab["sim"])
    with pytest.raises(SlipkitError, match="inside the slipkit dataset"):
        save_dataset(
            make_dataset(n_trials=2, n_frames=20), lab["sim"] / "streams" / "x"
        )
    with pytest.raises(SlipkitError, match="inside the slipkit dataset"):
        write_bundle(lab["sim"] / "b", linear_graph(np.ones(12), 0.0), manifest(12))
    assert before == _snapshot(lab["sim"])


def test_a_single_output_file_never_lands_inside_a_slipkit_folder(
    lab: dict[str, Path], tmp_path: Path
) -> None:
    """check_out_file (for options naming one file) refuses a dataset's manifest, a folder and a symlink, and accepts a plain file elsewhere."""
    (tmp_path / "link.json").symlink_to(tmp_path / "elsewhere.json")
    refused = []
    for path in (lab["sim"] / "manifest.json", lab["docs"], tmp_path / "link.json"):
        with pytest.raises(SlipkitError, match="refusing") as exc:
            _files.check_out_file(path, option="--json")
        refused.append(str(exc.value).startswith(f"--json={path}: "))
    summary = _files.check_out_file(tmp_path / "summary.json", option="--json")
    assert ([True] * 3, tmp_path / "summary.json") == (refused, summary)


# -- 5. permissions -------------------------------------------------------------------------
@pytest.fixture
def umask(request: pytest.FixtureRequest) -> Iterator[int]:
    mask = int(request.param)
    saved = os.umask(mask)
    try:
        yield mask
    finally:
        os.umask(saved)


@pytest.mark.parametrize(
    "umask", [0o022, 0o027], indirect=True, ids=["umask022", "umask027"]
)
def test_written_folders_and_files_follow_the_umask(umask: int, tmp_path: Path) -> None:
    """Datasets, bundles and text files get `0o777 & ~umask` (folders) and `0o666 & ~umask` (files), not 0700/0600."""
    ds = save_dataset(make_dataset(n_trials=2, n_frames=20), tmp_path / "ds")
    b = write_bundle(tmp_path / "b", linear_graph(np.ones(12), 0.0), manifest(12))
    atomic_write_text(tmp_path / "report.md", "x")
    modes = {
        p.relative_to(tmp_path).as_posix(): p.stat().st_mode & 0o777
        for p in [ds, *ds.rglob("*"), b, *b.rglob("*"), tmp_path / "report.md"]
    }
    expected = {
        k: (0o777 if (tmp_path / k).is_dir() else 0o666) & ~umask for k in modes
    }
    assert expected == modes


# -- 6. nothing outside the named out folders ----------------------------------------------
def test_commands_touch_nothing_but_their_own_out(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """simulate, import, train, evaluate and export in a tree of unrelated files change none of them and leave nothing else."""
    tree = tmp_path / "tree"
    _docs(tree / "recordings")
    (tree / ".hidden_config").write_text("keep me\n")
    (tree / "readme.txt").write_text("keep me too\n")
    (tree / "sim.bak").write_text("a file named like an out\n")
    _csv_source(tree / "csv")
    (tree / "link-to-recordings").symlink_to(tree / "recordings")
    before = _snapshot(tree)
    monkeypatch.chdir(tree)
    steps = [
        ["simulate", *SIM_OPTS, "n_trials=4", "out=sim"],
        ["import", *CSV_OPTS, "path=csv", "out=imp"],
        ["train", "experiment=fsr_roc", "dataset.path=sim", "run_dir=run"],
        ["evaluate", "run=run", "dataset=sim", "name=again"],
        [
            "export",
            "run=run",
            "out=bundle",
            "choose_session=false",
            "replay_max_frames=500",
            "parity.max_calls=500",
        ],
    ]
    codes = [_cli(args, capsys)[0] for args in steps]
    after = _snapshot(tree)
    outs = ("sim", "imp", "run", "bundle")
    new = {k for k in after if k not in before}
    assert [0] * len(steps) == codes
    assert before == {k: after.get(k) for k in before}
    assert set() == {k for k in new if k.split("/")[0] not in outs}
    assert [] == [k for k in after if ".tmp-" in k or ".old-" in k]
    assert {"again"} == {
        k.split("/")[2] for k in new if k.startswith("run/evaluations/")
    }


@pytest.fixture
def lab_tree(
    lab: dict[str, Path], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> Path:
    """The lab (a dataset, a run, a bundle, documents) beside a CSV recording, a readme,
    a best.json of the user's, a replay file, a symlink and a FIFO; the working directory."""
    tree = tmp_path / "lab"
    _csv_source(tree / "csv")
    (tree / "readme.txt").write_text("keep me\n")
    (tree / "link-to-docs").symlink_to(tree / "docs")
    (tree / "best.json").write_text('{"my": "best result"}\n')
    shutil.copy(lab["bundle"] / "replay.npz", tree / "r.npz")
    os.mkfifo(tree / "fifo")
    monkeypatch.chdir(tree)
    return tree


#: per command: its write options aimed at what it did not write (run in ``lab_tree``)
HOSTILE = {
    "evaluate": [
        ["evaluate", "run=run", "dataset=sim", "name=../../docs"],
        ["evaluate", "run=run", "dataset=sim", "name=<abs>/docs"],
        ["evaluate", "run=run", "dataset=sim", "name=../../fifo"],
    ],
    "import": [
        ["import", *CSV_OPTS, "path=csv", "out=csv", *OVER],
        ["import", *CSV_OPTS, "path=csv", "out=docs", *OVER],
        ["import", *CSV_OPTS, "path=csv", "out=fifo", *OVER],
    ],
    "simulate": [
        ["simulate", *SIM_OPTS, "out=readme.txt", *OVER],
        ["simulate", *SIM_OPTS, "out=link-to-docs", *OVER],
        ["simulate", *SIM_OPTS, "out=sim/streams/x.parquet"],
        ["simulate", *SIM_OPTS, "out=fifo", *OVER],
    ],
    "train": [
        ["train", "experiment=fsr_roc", "dataset.path=sim", "run_dir=sim", *OVER],
        ["train", "experiment=fsr_roc", "dataset.path=sim", "run_dir=docs", *OVER],
        ["train", "experiment=fsr_roc", "dataset.path=sim", "run_dir=fifo", *OVER],
    ],
    "export": [
        ["export", "run=run", "out=docs", *OVER],
        ["export", "run=run", "out=run/bundle"],
        ["export", "run=run", "out=fifo", *OVER],
    ],
    "compare+demo": [
        ["compare", "comparison=fsr", "out=docs", "progress=false", *OVER],
        ["compare", "comparison=fsr", "out=fifo", "progress=false", *OVER],
        ["demo", "out=docs", "quick=true", "progress=false"],
        ["demo", "out=fifo", "quick=true", "progress=false"],
    ],
}


@pytest.mark.parametrize("command", list(HOSTILE))
def test_hostile_outs_in_a_lab_tree_change_nothing(
    command: str, lab_tree: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Every write option of simulate, import, train, evaluate, export, compare and demo aimed at a file, folder, FIFO or slipkit folder it did not write exits 2; the tree stays byte-identical."""
    before = _snapshot(lab_tree)
    hostile = [
        [a.replace("<abs>", str(lab_tree)) for a in args] for args in HOSTILE[command]
    ]
    refused = [_cli(args, capsys)[0] for args in hostile]
    assert ([2] * len(hostile), before) == (refused, _snapshot(lab_tree))


#: a tiny `slipkit sweep` (tests/train/test_sweep_optuna.py): refused before its first trial
SWEEP = [
    "sweep",
    "experiment=tactip_svm",
    "dataset.n_trials=4",
    "task.cv=2",
    "search=tactip_svm",
    "n_trials=1",
]


def test_hostile_sweep_closedloop_and_json_outs_in_a_lab_tree_change_nothing(
    lab_tree: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """sweep's out and storage, closedloop's out and slipkit-run's --json aimed at what they did not write (a user's file or folder, a FIFO, a dataset, a bundle, an input) exit 2; the tree stays byte-identical."""
    from slipkit.runtime.cli import main as run_main

    before = _snapshot(lab_tree)
    hostile = [
        ["closedloop", "scenario=fsr", "out=docs", *OVER],
        ["closedloop", "scenario=fsr", "out=fifo", *OVER],
        ["closedloop", "scenario=fsr", "out=sim/loop"],
        [*SWEEP, "out=docs"],
        [*SWEEP, "out=."],
        [*SWEEP, "out=bundle"],
        [*SWEEP, "out=sim/sweep"],
        [*SWEEP, "out=fifo"],
        [*SWEEP, "out=new", "storage=sqlite:///sim/study.db"],
        [*SWEEP, "out=new", "storage=sqlite:///readme.txt"],
        [*SWEEP, "out=new", "storage=sqlite:///fifo"],
        [*SWEEP, "out=new", "storage=sqlite://"],
    ]
    runs = [
        ["bundle", "--json", "readme.txt"],
        ["bundle", "--json", "best.json"],
        ["bundle", "--json", "fifo"],
        ["bundle", "--json", "docs"],
        ["bundle", "--json", "link-to-docs"],
        ["bundle", "--json", "bundle/manifest.json"],
        ["bundle", "--json", "bundle/replay.npz"],
        ["bundle", "--replay", "r.npz", "--json", "r.npz"],
        ["--stream", "a=bundle@replay:r.npz", "--json", "r.npz"],
    ]
    refused = [_cli(args, capsys)[0] for args in hostile]
    for args in runs:
        with pytest.raises(SystemExit) as exc:
            run_main(args)
        refused.append(int(exc.value.code or 0))
    assert ([2] * (len(hostile) + len(runs)), before) == (refused, _snapshot(lab_tree))
