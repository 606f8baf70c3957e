"""Single output files and sweep folders: no command replaces what it did not write.

``slipkit-run --json`` replaces an existing file only when it is a slipkit-run summary,
and never one of the run's inputs, a FIFO, a device or a socket; ``slipkit sweep``
checks its ``out`` folder and its SQLite ``storage`` before creating anything. The
rules live in :mod:`slipkit._files` (``check_out_file``, ``write_out_file``, ``Layout``).
"""

from __future__ import annotations

import json
import os
import socket
import stat
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from tests.robustness.test_write_safety import _cli, _docs, _snapshot
from tests.runtime.helpers import linear_graph, manifest

from slipkit import _files
from slipkit.runtime import write_bundle
from slipkit.runtime.cli import SUMMARY_FORMAT, is_summary
from slipkit.runtime.cli import main as run_main

NOTES = b"months of lab notes: do not lose\n"


def _run(args: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str]:
    """``slipkit-run <args>`` in process: (exit status, stderr)."""
    capsys.readouterr()
    try:
        run_main(args)
        code = 0
    except SystemExit as exc:
        code = int(exc.code or 0)
    return code, capsys.readouterr().err


@pytest.fixture(scope="module")
def bundle_src(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A small bundle with a 10-frame replay, made once."""
    root = tmp_path_factory.mktemp("bundle")
    return write_bundle(
        root / "bundle",
        linear_graph(np.ones(12), 0.0),
        manifest(12),
        replay=(np.zeros((10, 3)), np.arange(10) / 100.0),
    )


@pytest.fixture
def lab(tmp_path: Path, bundle_src: Path) -> Path:
    """``tmp_path/lab``: a bundle, a replay file, a user's notes, a folder of documents."""
    import shutil

    base = tmp_path / "lab"
    base.mkdir()
    shutil.copytree(bundle_src, base / "bundle")
    shutil.copy(bundle_src / "replay.npz", base / "r.npz")
    (base / "notes.txt").write_bytes(NOTES)
    _docs(base / "docs")
    return base


# -- slipkit-run --json -----------------------------------------------------------------
def test_json_refuses_to_replace_a_users_own_file(
    lab: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """`slipkit-run B --json notes.txt` exits 2 in one line and the notes stay."""
    before = _snapshot(lab)
    code, err = _run([str(lab / "bundle"), "--json", str(lab / "notes.txt")], capsys)
    expected = (
        f"slipkit-run: error: --json={lab / 'notes.txt'}: exists and is not a "
        "slipkit-run summary; refusing to replace it\n"
    )
    assert (2, expected, before) == (code, err, _snapshot(lab))


@pytest.mark.parametrize("link", [False, True], ids=["same-path", "hard-link"])
def test_json_refuses_the_replay_it_reads(
    link: bool, lab: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """`--replay r.npz --json r.npz` (or a hard link of r.npz) exits 2 and r.npz stays a replay."""
    out = lab / "r.npz"
    if link:
        out = lab / "r-link.npz"
        os.link(lab / "r.npz", out)
    before = _snapshot(lab)
    code, err = _run(
        [str(lab / "bundle"), "--replay", str(lab / "r.npz"), "--json", str(out)],
        capsys,
    )
    assert (2, True, before) == (
        code,
        f"--json={out}: is the input --replay={lab / 'r.npz'}; refusing" in err,
        _snapshot(lab),
    )


def test_json_refuses_a_file_inside_its_bundle(
    lab: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """`--json <bundle>/replay.npz` (the replay the run reads by default) exits 2, the bundle intact."""
    before = _snapshot(lab)
    out = lab / "bundle" / "replay.npz"
    code, err = _run([str(lab / "bundle"), "--json", str(out)], capsys)
    assert (2, True, before) == (
        code,
        f"--json={out}: is inside the slipkit bundle " in err,
        _snapshot(lab),
    )


def _special(kind: str, path: Path) -> Any:
    """Make a FIFO, a UNIX socket or a character device (1, 3, as /dev/null) at ``path``."""
    if kind == "fifo":
        os.mkfifo(path)
        return None
    if kind == "socket":
        sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        sock.bind(str(path))
        return sock
    try:
        os.mknod(path, stat.S_IFCHR | 0o600, os.makedev(1, 3))
    except PermissionError:
        pytest.skip("creating a device node needs CAP_MKNOD")
    return None


@pytest.mark.parametrize(
    ("kind", "name"),
    [
        ("fifo", "a FIFO (named pipe)"),
        ("socket", "a socket"),
        ("device", "a character device"),
    ],
)
def test_json_refuses_a_fifo_a_socket_or_a_device(
    kind: str, name: str, lab: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """`--json <FIFO | socket | device node>` exits 2 before running (never opened, never replaced)."""
    out = lab / "special"
    held = _special(kind, out)
    try:
        mode = os.lstat(out).st_mode
        code, err = _run([str(lab / "bundle"), "--json", str(out)], capsys)
        after = os.lstat(out).st_mode
    finally:
        if held is not None:
            held.close()
    assert (2, True, mode) == (
        code,
        f"--json={out}: is {name}, not a regular file; refusing to write to it" in err,
        after,
    )


def test_json_rewrites_its_own_summary_with_a_format_marker(
    lab: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Run twice into one --json: both exit 0; the summary carries `format: slipkit-run-summary`."""
    out = lab / "summary.json"
    codes = [_run([str(lab / "bundle"), "--json", str(out)], capsys)[0] for _ in "ab"]
    summary = json.loads(out.read_text())
    assert ([0, 0], SUMMARY_FORMAT, 10) == (
        codes,
        summary["format"],
        summary["frames"],
    )


@pytest.mark.parametrize(
    ("text", "own"),
    [
        ('{"bundle": "b", "latency_ms": null, "budget_ms": {}}', True),
        ('{"bundle": "b", "session_candidates": []}', True),
        ('{"hand": {}, "streams": []}', True),
        ('{"format": "slipkit-run-summary"}', True),
        ('{"format": "my-notes", "hand": {}, "streams": []}', False),
        ('{"bundle": "my favourite"}', False),
        ("[1, 2, 3]", False),
        ("not json", False),
    ],
)
def test_a_summary_is_recognised_with_or_without_its_marker(
    text: str, own: bool, tmp_path: Path
) -> None:
    """Summaries written before the format marker stay replaceable; other JSON is not a summary."""
    path = tmp_path / "s.json"
    path.write_text(text)
    assert own == is_summary(path)


def test_a_file_whose_name_appears_meanwhile_is_not_replaced(tmp_path: Path) -> None:
    """write_out_file checks again at the write: a user's file made during the run is kept."""
    path = tmp_path / "summary.json"
    _files.check_out_file(path, option="--json", is_own=is_summary)
    path.write_bytes(NOTES)
    with pytest.raises(_files.SlipkitError, match="exists and is not"):
        _files.write_out_file(path, "{}", option="--json", is_own=is_summary)
    assert NOTES == path.read_bytes()


def test_a_failed_single_file_write_names_the_option_and_leaves_no_folder(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A write that fails (read-only folder, full disk) is one error naming the option; the parents it made are gone."""

    def refuse(path: Path | str, text: str) -> None:
        raise PermissionError(13, "Permission denied")

    monkeypatch.setattr(_files, "atomic_write_text", refuse)
    with pytest.raises(_files.SlipkitError) as exc:
        _files.write_out_file(tmp_path / "a" / "b" / "s.json", "{}", option="--json")
    assert (
        f"--json={tmp_path / 'a' / 'b' / 's.json'}: cannot write it: Permission denied",
        [],
    ) == (
        str(exc.value),
        sorted(p.name for p in tmp_path.iterdir()),
    )


# -- slipkit sweep: out and storage ------------------------------------------------------
#: a tiny TacTip experiment (tests/train/test_sweep_optuna.py): < 1 s a trial
TINY = [
    "experiment=tactip_svm",
    "dataset.n_trials=4",
    "scene.model.n_pins=19",
    "scene.model.duration_s=1.0",
    "scene.model.onset_s=[0.4,0.7]",
    "task.cv=2",
    "search=tactip_svm",
    "n_trials=1",
]


@pytest.fixture
def sweep_lab(lab: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """The lab beside a dataset folder, a user's own SQLite database and a best.json of theirs; the working directory."""
    import sqlite3

    from tests.strategies import make_dataset

    from slipkit.data.io import save_dataset

    save_dataset(make_dataset(n_trials=2, n_frames=10), lab / "ds")
    con = sqlite3.connect(lab / "mine.db")
    con.execute("CREATE TABLE samples (x REAL)")
    con.commit()
    con.close()
    (lab / "docs" / "best.json").write_text('{"my": "best result"}\n')
    monkeypatch.chdir(lab)
    return lab


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (
            ["out=s", "storage=sqlite:///ds/study.db"],
            "storage=ds/study.db: is inside the slipkit dataset ",
        ),
        (["out=bundle"], "out=bundle: exists and is not a slipkit sweep"),
        (["out=docs"], "out=docs: exists and is not a slipkit sweep"),
        (["out=ds/sweep"], "out=ds/sweep: is inside the slipkit dataset "),
        (["out=s", "storage=sqlite://"], "storage=sqlite://: an in-memory database"),
        (
            ["out=s", "storage=sqlite:///:memory:"],
            "storage=sqlite:///:memory:: an in-memory database",
        ),
        (
            ["out=s", "storage='sqlite:///file:r.db?mode=ro&uri=true'"],
            "opened read-only; a sweep writes its trials into the study",
        ),
        (
            ["out=s", "storage=sqlite:///notes.txt"],
            "storage=notes.txt: exists and is not an Optuna study database",
        ),
        (
            ["out=s", "storage=sqlite:///mine.db"],
            "storage=mine.db: exists and is not an Optuna study database",
        ),
        (
            ["out=s", "storage=sqlite:///docs"],
            "storage=docs: is a folder; refusing to replace it",
        ),
        (
            ["out=s", "heartbeat_s=1e12", "grace_s=2e12"],
            "heartbeat_s=1000000000000.0: expected a whole number in [1, 86400]",
        ),
        (["out=notes.txt/s"], "out=notes.txt/s: cannot create it: Not a directory"),
    ],
    ids=[
        "db-in-dataset",
        "out-bundle",
        "out-docs",
        "out-in-dataset",
        "memory",
        "memory-named",
        "read-only-uri",
        "db-is-notes",
        "db-is-another-database",
        "db-is-folder",
        "heartbeat-overflow",
        "out-under-a-file",
    ],
)
def test_sweep_refuses_outs_it_did_not_write_before_creating_anything(
    args: list[str],
    message: str,
    sweep_lab: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    """`slipkit sweep` aimed at a dataset, a bundle, a user's folder, file or database, an in-memory or read-only study: exit 2 in one line, the lab byte-identical."""
    before = _snapshot(sweep_lab)
    code, err = _cli(["sweep", *TINY, *args], capsys)
    assert (2, True, 1, before) == (
        code,
        message in err,
        len(err.strip().splitlines()),
        _snapshot(sweep_lab),
    ), err


def test_sweep_refuses_a_folder_or_database_it_cannot_write(
    sweep_lab: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    """A read-only sweep folder or study database is one line naming `out` / `storage`, exit 2, not an internal error."""
    import tempfile

    from slipkit.train import optuna_sweep

    real = tempfile.TemporaryFile

    def read_only(*args: Any, dir: Any = None, **kwargs: Any) -> Any:
        if dir is not None and Path(dir).name == "s":
            raise PermissionError(13, "Permission denied")
        return real(*args, dir=dir, **kwargs)

    assert 0 == _cli(["sweep", *TINY, "out=s"], capsys)[0]
    monkeypatch.setattr(_files.tempfile, "TemporaryFile", read_only)
    folder = _cli(["sweep", *TINY, "n_trials=2", "out=s"], capsys)
    monkeypatch.undo()
    monkeypatch.chdir(sweep_lab)
    monkeypatch.setattr(optuna_sweep.os, "access", lambda *a, **k: False)
    db = _cli(["sweep", *TINY, "n_trials=2", "out=s"], capsys)
    assert (
        (2, "slipkit sweep: error: out=s: cannot write there: Permission denied\n"),
        (2, True),
    ) == (folder, (db[0], "/s/study.db: the database file is read-only" in db[1]))


def test_a_study_database_that_refuses_writes_is_named(tmp_path: Path) -> None:
    """Joining a study in a database that cannot be written is a one-line error naming `storage`."""
    from slipkit.train import optuna_sweep

    db = tmp_path / "study.db"
    kw = {"heartbeat_s": 60, "grace_s": 180, "max_retry": 1}
    optuna_sweep.open_storage(f"sqlite:///{db}", **kw)  # an empty Optuna database
    url = f"sqlite:///file:{db}?mode=ro&uri=true"
    storage = optuna_sweep.open_storage(url, **kw)
    obj = optuna_sweep.Objective("validation.accuracy", "maximize")
    with pytest.raises(_files.SlipkitError) as exc:
        optuna_sweep._joined_study(storage, "s", url, obj, 0, {})
    text = str(exc.value)
    assert (True, True) == (
        text.startswith("storage=sqlite:///"),
        text.endswith("cannot write the study: attempt to write a readonly database"),
    )


def test_sweep_resumes_in_its_own_folder(
    sweep_lab: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A second `slipkit sweep` into its own out (study.db, trials/, best.json) joins the study and adds its trial."""
    first = _cli(["sweep", *TINY, "out=s"], capsys)[0]
    second = _cli(["sweep", *TINY, "n_trials=2", "out=s"], capsys)[0]
    best = json.loads((sweep_lab / "s" / "best.json").read_text())
    assert (0, 0, 2, ["0000", "0001"]) == (
        first,
        second,
        best["n_complete"],
        sorted(p.name for p in (sweep_lab / "s" / "trials").iterdir()),
    )


# -- slipkit train -m: the multirun's summary files ---------------------------------------
def test_a_multirun_summary_never_replaces_a_users_best_json(tmp_path: Path) -> None:
    """A sweep folder (hydra.sweep.dir) holding the user's own best.json: the summary is refused naming it, the file kept."""
    from slipkit.train.sweep import JOB_FILE, summarise_sweep

    (tmp_path / "0").mkdir()
    job = {
        "job": 0,
        "run_dir": str(tmp_path / "run"),
        "overrides": ["seed=0"],
        "objective": {"name": "validation.x", "direction": "maximize", "value": 1.0},
    }
    (tmp_path / "0" / JOB_FILE).write_text(json.dumps(job))
    (tmp_path / "best.json").write_bytes(NOTES)
    with pytest.raises(_files.SlipkitError) as exc:
        summarise_sweep(tmp_path)
    assert (True, NOTES) == (
        str(exc.value).endswith(
            "exists and is not a multirun best.json; refusing to replace it"
        ),
        (tmp_path / "best.json").read_bytes(),
    )
