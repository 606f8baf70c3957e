"""Hostile command lines (issue 12): the `slipkit` command never prints a traceback.

Every malformed call of every subcommand ends in one line on stderr,
``slipkit <sub>: error: ...`` naming the option, and exit status 2, before any
work starts; an exception that is not a SlipkitError (a bug) ends in one line
``slipkit <sub>: internal error ...`` naming the log file holding the traceback.
Commands run through the in-process CLI (``slipkit.cli.main``), as a user types them.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest
from tests.strategies import make_dataset

import slipkit.train.commands as train_commands
from slipkit.cli import main
from slipkit.data import save_dataset
from slipkit.data.dataset import Dataset
from slipkit.errors import SlipkitError
from slipkit.train.commands import check_trainable


@pytest.fixture(autouse=True)
def _sandbox(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Relative outputs and internal-error logs land under tmp_path only."""
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("SLIPKIT_LOG_DIR", str(tmp_path / "logs"))
    monkeypatch.setenv("SLIPKIT_DATA", str(tmp_path / "no-recordings"))
    monkeypatch.delenv("HYDRA_FULL_ERROR", raising=False)


def cli(args: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[Any, list[str]]:
    """(exit status, non-blank stderr lines) of ``slipkit <args>``; status 0 if it returned."""
    capsys.readouterr()
    try:
        main(args)
        code: Any = 0
    except SystemExit as exc:
        code = exc.code
    err = capsys.readouterr().err
    return code, [line for line in err.splitlines() if line.strip()]


def files_under(path: Path) -> set[str]:
    return {str(p.relative_to(path)) for p in path.rglob("*")}


@pytest.fixture
def recording(tmp_path: Path) -> Path:
    """A three-row CSV recording for `slipkit import`."""
    path = tmp_path / "rec.csv"
    path.write_text("t,a\n0.0,1.0\n0.1,2.0\n0.2,3.0\n", encoding="utf-8")
    return path


@pytest.fixture
def dataset_folder(tmp_path: Path) -> Path:
    return save_dataset(make_dataset(n_trials=2), tmp_path / "ds")


# (arguments, the one line expected on stderr); {tmp}, {csv}, {ds} are filled in.
MALFORMED: list[tuple[list[str], str]] = [
    # simulate: numbers Hydra typed as floats, text or booleans
    (["simulate", "n_trials=2.9"], "n_trials=2.9: expected a whole number >= 1"),
    (["simulate", "n_trials=abc"], "n_trials=abc: expected a whole number >= 1"),
    (["simulate", "n_trials=0"], "n_trials=0: expected a whole number >= 1"),
    (["simulate", "n_trials=true"], "n_trials=true: expected a whole number >= 1"),
    (["simulate", "seed=1.5"], "seed=1.5: expected a whole number in [0, 4294967295]"),
    (["simulate", "seed=abc"], "seed=abc: expected a whole number in [0, 4294967295]"),
    (["simulate", "seed=-1"], "seed=-1: expected a whole number in [0, 4294967295]"),
    (
        ["simulate", "scene.model.rate_hz=abc"],
        "scene.model.rate_hz=abc: expected a number in [1, 100000] Hz",
    ),
    (
        ["simulate", "scene.model.rate_hz=true"],
        "scene.model.rate_hz=true: expected a number in [1, 100000] Hz",
    ),
    (
        ["simulate", "scene=biotac_lift_slip", "scene.model.pac_rate_hz=nan"],
        "scene.model.pac_rate_hz=nan: expected a number in [1, 100000] Hz",
    ),
    (
        ["simulate", "scene.effects.white_noise.sigma=abc", "out={tmp}/s"],
        "scene.effects.white_noise.sigma: expected a finite number or [lo, hi]; got 'abc'",
    ),
    (["simulate", "overwrite=yes"], "overwrite=yes: expected true or false"),
    (["simulate", "progress=2"], "progress=2: expected true or false"),
    (["simulate", "out=${nope}"], "out: Interpolation key 'nope' not found"),
    (["simulate", "n_trials=["], "n_trials=[: no viable alternative at input '['"),
    (["simulate", "--bogus"], "unrecognized arguments: --bogus"),
    (["simulate", "scene=nope"], "Could not find 'scene/nope'; available: "),
    (
        ["simulate", "scene=davis_release", "scene.model.rate_hz=1"],
        "scene.model.rate_hz: unknown key; did you mean scene.model.truth_rate_hz?",
    ),
    # import
    (["import", "out={tmp}/o"], "path=...: missing; this option is required"),
    (["import", "path={csv}"], "out=...: missing; this option is required"),
    (
        ["import", "path={csv}", "out={tmp}/o", "source.rate_hz=abc"],
        "source.rate_hz=abc: expected a finite number > 0 or null",
    ),
    (
        ["import", "path={csv}", "out={tmp}/o", "source.rate_hz=true"],
        "source.rate_hz=true: expected a finite number > 0 or null",
    ),
    (
        ["import", "path={csv}", "out={tmp}/o", "source.rate_hz=-5"],
        "source.rate_hz=-5: expected a finite number > 0 or null",
    ),
    (
        ["import", "path={csv}", "out={tmp}/o", "overwrite=1"],
        "overwrite=1: expected true or false",
    ),
    (["import", "source=nope", "path={csv}"], "Could not find 'source/nope'"),
    # info
    (["info"], "dataset=...: missing; this option is required"),
    (["info", "dataset={ds}", "verify=maybe"], "verify=maybe: expected true or false"),
    (["info", "dataset={ds}", "json=1"], "json=1: expected true or false"),
    # export-dataset
    (["export-dataset", "dataset={ds}"], "out=...: missing; this option is required"),
    (
        ["export-dataset", "dataset={ds}", "out={tmp}/lr", "overwrite=maybe"],
        "overwrite=maybe: expected true or false",
    ),
    # sweep (one Optuna study over train runs)
    (["sweep", "experiment=tactip_svm"], "search=...: missing; this option is"),
    (["sweep", "search=tactip_svm", "n_trials=2.9"], "n_trials=2.9: expected a whole"),
    (["sweep", "search=nope"], "Could not find 'search/nope'; available: "),
    (
        ["sweep", "search=tactip_svm", "search.params.model.C.low=0"],
        "search.params.model.C: ",
    ),
    (
        ["sweep", "search=tactip_svm", "storage=nonsense"],
        "storage=nonsense: not a database URL",
    ),
    (
        ["sweep", "search=tactip_svm", "grace_s=30", "heartbeat_s=60"],
        "grace_s=30: must exceed heartbeat_s=60",
    ),
    # train
    (["train", "experiment=nope"], "Could not find 'experiment/nope'; available: "),
    (["train", "seed=-1"], "seed=-1: expected a whole number in [0, 4294967295]"),
    # a run name is one folder under runs_dir: no escaping it
    (["train", "name=../../x"], "name=../../x: expected a plain folder name"),
    (["train", "name=/abs/x"], "name=/abs/x: expected a plain folder name"),
    (
        ["compare", "comparison=fsr", "comparison.name=../x"],
        "comparison.name=../x: expected a plain folder name",
    ),
    (
        ["train", "seed=4294967296"],
        "seed=4294967296: expected a whole number in [0, 4294967295]",
    ),
    (
        ["train", "dataset.n_trials=0"],
        "dataset.n_trials=0: expected a whole number >= 1",
    ),
    (
        ["train", "dataset.n_trials=2.9"],
        "dataset.n_trials=2.9: expected a whole number >= 1",
    ),
    (
        ["train", "dataset.seed=abc"],
        "dataset.seed=abc: expected a whole number in [0, 4294967295]",
    ),
    (
        ["train", "scene.model.rate_hz=true"],
        "scene.model.rate_hz=true: expected a number in [1, 100000] Hz",
    ),
    (["train", "overwrite=1"], "overwrite=1: expected true or false"),
    (
        ["train", "dataset.n_trials=2", "+model.bogus=1", "run_dir={tmp}/run"],
        "model.bogus: unknown key; model has C, class_weight, features, gamma,",
    ),
    (
        ["train", "model.C=abc", "run_dir={tmp}/run"],
        "model: The 'C' parameter of TacTipSVM must be a float in the range (0.0, inf). "
        "Got 'abc' instead.",
    ),
    (
        ["train", "experiment=fsr_roc", "detector.block=0", "run_dir={tmp}/run"],
        "detector: The 'block' parameter of FSRTouchSlip must be an int in the range "
        "[1, inf). Got 0 instead.",
    ),
    (
        ["train", "dataset.n_trials=4", "task.test_size=abc", "run_dir={tmp}/run"],
        "test_size must be a number in [0, 1); got 'abc'",
    ),
    (
        ["train", "task.variant=nope", "run_dir={tmp}/run"],
        "task.variant=nope: expected one of dr_dtheta, dr, dtheta",
    ),
    # evaluate
    (["evaluate"], "run=...: missing; this option is required"),
    (["evaluate", "run={tmp}/run"], "dataset=...: missing; this option is required"),
    (["evaluate", "run=", "dataset={ds}"], "run=: expected a path"),
    # export
    (["export"], "run=...: missing; this option is required"),
    (
        ["export", "run={tmp}/run", "opset=16"],
        "opset=16: expected a whole number in [17, 18]",
    ),
    (
        ["export", "run={tmp}/run", "debounce_k=0"],
        "debounce_k=0: expected a whole number >= 1 or null",
    ),
    (
        ["export", "run={tmp}/run", "parity.atol=abc"],
        "parity.atol=abc: expected a finite number >= 0",
    ),
    # compare
    (["compare", "comparison=nope"], "Could not find 'comparison/nope'; available: "),
    (["compare", "seed=1.5"], "seed=1.5: expected a whole number in [0, 4294967295]"),
    (
        ["compare", "comparison.dataset.n_trials=abc"],
        "comparison.dataset.n_trials=abc: expected a whole number >= 1",
    ),
    (
        ["compare", "cost.max_frames=0"],
        "cost.max_frames=0: expected a whole number >= 1",
    ),
    (["compare", "cost.export=no"], "cost.export=no: expected true or false"),
    (
        [
            "compare",
            "comparison=fsr",
            "comparison.estimators.fsr_paper.threshold=abc",
            "out={tmp}/cmp",
        ],
        "comparison.estimators.fsr_paper: The 'threshold' parameter of FSRTouchSlip "
        "must be an instance of 'float' or None. Got 'abc' instead.",
    ),
    # closedloop
    (
        ["closedloop", "out={tmp}/cl", "seeds=[0,1.5]"],
        "seeds=[0, 1.5]: expected a non-empty list of whole numbers in [0, 4294967295]",
    ),
    (
        ["closedloop", "out={tmp}/cl", "seeds=3"],
        "seeds=3: expected a non-empty list of whole numbers in [0, 4294967295]",
    ),
    (
        ["closedloop", "out={tmp}/cl", "trials_per_speed=0"],
        "trials_per_speed=0: expected a whole number in [1, 1000] or null",
    ),
    (
        ["closedloop", "out={tmp}/cl", "train_trials=2.5"],
        "train_trials=2.5: expected a whole number in [1, 10000] or null",
    ),
    (
        ["closedloop", "out={tmp}/cl", "overwrite=yes"],
        "overwrite=yes: expected true or false",
    ),
    (
        ["closedloop", "closedloop=nope"],
        "Could not find 'closedloop/nope'; available: ",
    ),
    # demo (out= under tmp_path even though nothing may be written)
    (["demo", "out={tmp}/demo", "quick=maybe"], "quick=maybe: expected true or false"),
    (
        ["demo", "out={tmp}/demo", "seed=-1"],
        "seed=-1: expected a whole number in [0, 4294967295]",
    ),
    (
        ["demo", "out={tmp}/demo", "replay.max_frames=abc"],
        "replay.max_frames=abc: expected a whole number >= 1",
    ),
]


@pytest.mark.parametrize(
    ("args", "message"),
    [pytest.param(*case, id=" ".join(case[0])) for case in MALFORMED],
)
def test_malformed_options_end_in_one_line(
    args: list[str],
    message: str,
    tmp_path: Path,
    recording: Path,
    dataset_folder: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    """A malformed option ends in one stderr line naming it, exit 2, and writes nothing."""
    filled = [
        a.format(tmp=tmp_path, csv=recording, ds=dataset_folder)
        if "{" in a and "${" not in a
        else a
        for a in args
    ]
    before = files_under(tmp_path)
    code, lines = cli(filled, capsys)
    assert (2, 1) == (code, len(lines)), lines
    assert lines[0].startswith(f"slipkit {args[0]}: error: "), lines[0]
    assert message in lines[0]
    assert before == files_under(tmp_path)


def test_every_subcommand_is_covered() -> None:
    """The malformed cases reach every subcommand of the CLI."""
    from slipkit.cli import SUBCOMMANDS

    assert set(SUBCOMMANDS) == {args[0] for args, _ in MALFORMED}


# -- the last-resort net --------------------------------------------------------------
def test_a_bug_is_one_line_with_the_traceback_in_a_log(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """An exception that is not a SlipkitError prints one 'internal error' line naming the log."""
    import slipkit.data.commands as data_commands

    def broken(cfg: Any) -> None:
        raise RuntimeError("boom\nsecond line")

    monkeypatch.setattr(data_commands, "info_main", broken)
    code, lines = cli(["info", f"dataset={tmp_path}"], capsys)
    assert (1, 1) == (code, len(lines)), lines
    head = "slipkit info: internal error (a bug, please report it): RuntimeError: boom; second line (traceback in "
    assert lines[0].startswith(head), lines[0]
    log = Path(lines[0][len(head) : -1])
    assert tmp_path / "logs" == log.parent
    text = log.read_text(encoding="utf-8")
    assert (True, True) == ("Traceback" in text, "boom" in text)


def test_hydra_full_error_does_not_bring_the_traceback_back(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """With HYDRA_FULL_ERROR=1 set by the user, errors are still one line; the variable is kept."""
    monkeypatch.setenv("HYDRA_FULL_ERROR", "1")
    code, lines = cli(["export"], capsys)
    assert (
        2,
        ["slipkit export: error: run=...: missing; this option is required"],
    ) == (code, lines)
    code, lines = cli(["compare", "comparison=nope"], capsys)  # Hydra's own error
    assert (2, 1) == (code, len(lines)), lines
    assert lines[0].startswith(
        "slipkit compare: error: In 'compare': Could not find 'comparison/nope'; "
        "available: biotac_force, "
    ), lines[0]
    assert "1" == os.environ.get("HYDRA_FULL_ERROR")


def test_the_cli_leaves_hydra_full_error_unset(
    capsys: pytest.CaptureFixture[str],
) -> None:
    """The CLI sets HYDRA_FULL_ERROR only while Hydra runs, then removes it again."""
    cli(["compare", "comparison=nope"], capsys)
    assert None is os.environ.get("HYDRA_FULL_ERROR")


def test_console_script_prints_one_line(tmp_path: Path) -> None:
    """The installed `slipkit` entry point, in a fresh process, prints one line and exits 2."""
    exe = Path(sys.executable).with_name("slipkit")
    env = {k: v for k, v in os.environ.items() if k != "HYDRA_FULL_ERROR"}
    result = subprocess.run(
        [str(exe), "simulate", "n_trials=2.9", f"out={tmp_path / 'sim'}"],
        capture_output=True,
        text=True,
        check=False,
        env=env,
        cwd=tmp_path,
    )
    assert (
        2,
        ["slipkit simulate: error: n_trials=2.9: expected a whole number >= 1"],
    ) == (result.returncode, result.stderr.splitlines())
    assert not (tmp_path / "sim").exists()


# -- evaluate: a dataset from another sensor or layout ------------------------------
@pytest.fixture(scope="module")
def tactip_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A small TacTip SVM run (127 pins: 254 features)."""
    run = tmp_path_factory.mktemp("tactip") / "run"
    main(
        [
            "train",
            "experiment=tactip_svm",
            "dataset.n_trials=4",
            "task.search.n_trials=2",
            "task.search.cv=2",
            f"run_dir={run}",
        ]
    )
    return run


@pytest.fixture(scope="module")
def other_datasets(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """A 331-pin TacTip dataset and a SlipTack dataset (one trial each)."""
    root = tmp_path_factory.mktemp("other")
    common = ["n_trials=1", "progress=false", "summary=false"]
    main(
        [
            "simulate",
            "scene=tactip_gravity_drop",
            "scene.model.n_pins=331",
            *common,
            f"out={root / 'pins331'}",
        ]
    )
    main(["simulate", "scene=sliptack_pull", *common, f"out={root / 'sliptack'}"])
    return {"pins331": root / "pins331", "sliptack": root / "sliptack"}


def test_evaluate_refuses_another_pin_count(
    tactip_run: Path,
    other_datasets: dict[str, Path],
    capsys: pytest.CaptureFixture[str],
) -> None:
    """A 331-pin TacTip dataset on a 127-pin run: one line naming both channel counts."""
    code, lines = cli(
        ["evaluate", f"run={tactip_run}", f"dataset={other_datasets['pins331']}"],
        capsys,
    )
    assert (2, 1) == (code, len(lines)), lines
    assert (
        f"does not fit run {tactip_run}: stream 'pins' has 662 channels [x0, x1, x2, x3, ...], "
        "the run was trained on 'tactip_gravity_drop' with 254 [x0, x1, x2, x3, ...]"
    ) in lines[0]
    assert not (tactip_run / "evaluations").exists()


def test_evaluate_refuses_another_sensor(
    tactip_run: Path,
    other_datasets: dict[str, Path],
    capsys: pytest.CaptureFixture[str],
) -> None:
    """A SlipTack dataset on a TacTip run: one line naming both sensors."""
    code, lines = cli(
        ["evaluate", f"run={tactip_run}", f"dataset={other_datasets['sliptack']}"],
        capsys,
    )
    assert (2, 1) == (code, len(lines)), lines
    assert (
        "the run was trained on 'tactip_gravity_drop' from sensor 'tactip', this "
        "dataset is from sensor 'sliptack'"
    ) in lines[0]


# -- train: too little data for the task ---------------------------------------------
@pytest.mark.parametrize(
    ("args", "message"),
    [
        (
            ["experiment=tactip_svm", "dataset.n_trials=1"],
            "cannot split 1 trials into test 50% and val 0% with at least one on every side",
        ),
        (
            ["experiment=tactip_svm", "dataset.n_trials=2"],
            "group CV (1 fold(s)) needs >= 2 trials on the training side; got 1",
        ),
        (
            ["experiment=sliptack_accel", "dataset.n_trials=2"],
            "DropAcceleration(frequency_slope): fewer than 2 distinct feature values",
        ),
    ],
    ids=["one-trial", "one-training-trial", "sliptack-accel-one-training-trial"],
)
def test_train_with_too_few_trials_is_one_line(
    args: list[str], message: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A task left with an empty side (or one trial to cross-validate) refuses in one line."""
    code, lines = cli(["train", *args, f"run_dir={tmp_path / 'run'}"], capsys)
    errors = [line for line in lines if line.startswith("slipkit train:")]
    assert (2, 1) == (code, len(errors)), lines
    assert message in errors[0]
    assert "Traceback" not in "\n".join(lines)
    assert not (tmp_path / "run").exists()


def _with_tables(ds: Dataset, tables: dict[str, Any], trials: Any = None) -> Dataset:
    return Dataset(
        sensor=ds.sensor,
        streams=ds.streams,
        trials=ds.trials if trials is None else trials,
        tables=tables,
        labels=ds.labels,
        groups=ds.groups,
        provenance=ds.provenance,
        name=ds.name,
    )


def test_training_refuses_an_all_nan_channel() -> None:
    """A channel the estimator reads with no finite value is refused before fitting."""
    ds = make_dataset(n_trials=3, with_events=False)
    force = ds.tables["force"].copy()
    force["fy"] = np.nan
    bad = _with_tables(ds, {"force": force})
    task = SimpleNamespace(stream="force", channels=None)
    with pytest.raises(SlipkitError) as exc:
        check_trainable(bad, task)  # type: ignore[arg-type]
    assert (
        "dataset 'tiny': stream 'force' channel 'fy' has no finite value in its 900 rows "
        "(all NaN or infinite); there is nothing to train on"
    ) == str(exc.value)


def test_training_refuses_a_dataset_without_trials() -> None:
    """A dataset of 0 trials (e.g. from an importer) is refused before fitting."""
    ds = make_dataset(n_trials=2, with_events=False)
    empty = _with_tables(ds, {"force": ds.tables["force"].iloc[:0]}, ds.trials.iloc[:0])
    with pytest.raises(SlipkitError) as exc:
        check_trainable(empty, SimpleNamespace(stream="force"))  # type: ignore[arg-type]
    assert "dataset 'tiny' holds no trials; there is nothing to train on" == str(
        exc.value
    )


def test_training_refuses_a_stream_the_task_reads_but_the_data_lacks() -> None:
    """task.stream naming a stream the dataset does not hold is refused in one line."""
    ds = make_dataset(n_trials=2, with_events=False)
    with pytest.raises(SlipkitError) as exc:
        check_trainable(ds, SimpleNamespace(stream="pac"))  # type: ignore[arg-type]
    assert (
        "task.stream=pac: dataset 'tiny' (sensor 'biotac') holds no stream 'pac'; "
        "streams: ['force']"
    ) == str(exc.value)


# -- compare: an estimator the family's task or data cannot feed ---------------------
@pytest.fixture
def no_training(monkeypatch: pytest.MonkeyPatch) -> list[Any]:
    """Calls of train_main (a refused comparison must make none)."""
    calls: list[Any] = []

    def spy(cfg: Any) -> float:
        calls.append(cfg)
        raise AssertionError("training started")

    monkeypatch.setattr(train_commands, "train_main", spy)
    return calls


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (
            [
                "comparison=dos_real",
                "+detector@comparison.estimators.pv=pressure_vibration",
            ],
            "comparison 'dos_real': estimator 'pv' (PressureVibration) cannot run in this "
            "family's task: WindowClassification fits a learned classifier on windows of "
            "stream 'electrodes'",
        ),
        (
            ["comparison=fsr", "+model@comparison.estimators.mlp=window_mlp"],
            "comparison 'fsr': estimator 'mlp' (WindowMLP) cannot run in this family's "
            "task: StreamDetection runs an analytic stream detector (StreamDetector) on "
            "stream 'fsr'",
        ),
        (
            ["comparison=fsr", "+detector@comparison.estimators.pv=pressure_vibration"],
            "comparison 'fsr': estimator 'pv': rate_hz=2200 Hz, but stream 'fsr' of the "
            "family's data is sampled at 2000 Hz",
        ),
        (
            ["comparison=sliptack", "+detector@comparison.estimators.fsr=fsr"],
            "comparison 'sliptack': estimator 'fsr' (FSRTouchSlip) cannot run in this "
            "family's task: SlipTackSpeed runs the SlipTack speed estimator",
        ),
        (
            [
                "comparison=biotac_slip_type",
                "comparison.estimators.window_cnn.n_channels=24",
            ],
            "comparison 'biotac_slip_type': estimator 'window_cnn': n_channels=24, but "
            "stream 'electrodes' of the family's data has 19 channel(s)",
        ),
    ],
    ids=[
        "dos-real-pressure",
        "fsr-window-mlp",
        "fsr-pressure-rate",
        "sliptack-fsr",
        "cnn-channels",
    ],
)
def test_compare_refuses_an_estimator_before_any_training(
    args: list[str],
    message: str,
    tmp_path: Path,
    no_training: list[Any],
    capsys: pytest.CaptureFixture[str],
) -> None:
    """An estimator that cannot read the family's stream is refused in one line; nothing trains."""
    code, lines = cli(
        ["compare", *args, f"out={tmp_path / 'cmp'}", "progress=false"], capsys
    )
    assert (2, 1) == (code, len(lines)), lines
    assert message in lines[0]
    assert [] == no_training
    assert not (tmp_path / "cmp").exists()
