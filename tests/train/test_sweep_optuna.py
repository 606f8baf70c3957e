"""`slipkit sweep`: one Optuna study over train runs, shared by worker processes."""

from __future__ import annotations

import json
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pytest

from slipkit.errors import SlipkitError
from slipkit.train.optuna_sweep import override, read_space, train_overrides

#: a tiny TacTip experiment: 4 short trials of 19 pins, 2-fold validation (< 1 s a run)
TINY = [
    "experiment=tactip_svm",
    "dataset.n_trials=4",
    "scene.model.n_pins=19",
    "scene.model.duration_s=1.0",
    "scene.model.onset_s=[0.4,0.7]",
    "task.cv=2",
]
STUDY = "tactip_svm-tactip_svm"


def _worker(out: Path, n_trials: int, *extra: str) -> list[str]:
    return [
        sys.executable,
        "-c",
        "from slipkit.cli import main; main()",
        "sweep",
        *TINY,
        "search=tactip_svm",
        f"n_trials={n_trials}",
        f"out={out}",
        "heartbeat_s=1",
        "grace_s=2",
        *extra,
    ]


def _trials(out: Path) -> list[Any]:
    import optuna

    study = optuna.load_study(study_name=STUDY, storage=f"sqlite:///{out}/study.db")
    return study.get_trials(deepcopy=False)


def _complete(trials: list[Any]) -> list[Any]:
    from optuna.trial import TrialState

    return [t for t in trials if t.state == TrialState.COMPLETE]


def test_two_workers_share_one_study(tmp_path: Path) -> None:
    """Two workers on one study run 4 trials between them, each once, in its own folder."""
    out = tmp_path / "sweep"
    workers = [
        subprocess.Popen(
            _worker(out, 4), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
        )
        for _ in range(2)
    ]
    done = [w.communicate(timeout=300) for w in workers]
    assert [0, 0] == [w.returncode for w in workers], [e[-2000:] for _, e in done]
    trials = _trials(out)
    complete = _complete(trials)
    assert 4 == len(complete)
    # Nothing left running or queued; any other trial was asked for and never run.
    others = [t for t in trials if t not in complete]
    assert [True] * len(others) == ["not_run" in t.user_attrs for t in others]
    run_dirs = sorted(t.user_attrs["run_dir"] for t in complete)
    assert 4 == len(set(run_dirs))
    assert run_dirs == sorted(str(p) for p in (out / "trials").iterdir())
    assert 4 == len({tuple(sorted(t.params.items())) for t in complete})
    for t in complete:
        run = json.loads((Path(t.user_attrs["run_dir"]) / "run.json").read_text())
        assert (t.value, t.value) == (
            run["objective"]["value"],
            t.user_attrs["validation_score"],
        )
    # Both workers print the same best run: the highest validation score.
    best = json.loads((out / "best.json").read_text())
    top = max(complete, key=lambda t: t.value)
    assert (top.value, top.user_attrs["run_dir"]) == (
        best["objective"]["value"],
        best["run_dir"],
    )
    assert "validation.balanced_accuracy" == best["objective"]["name"]
    for stdout, _ in done:
        assert str(out / "best.json") == stdout.splitlines()[-1]


def test_killed_worker_study_resumes(tmp_path: Path) -> None:
    """A worker killed mid-trial leaves a study a new worker finishes, retrying that trial."""
    from optuna.trial import TrialState

    out = tmp_path / "sweep"
    first = subprocess.Popen(
        _worker(out, 2), stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True
    )
    killed = None
    deadline = time.monotonic() + 120
    while killed is None and time.monotonic() < deadline and first.poll() is None:
        if (out / "study.db").is_file():
            try:
                # a trial that is training (its parameters drawn, its run folder named)
                running = [
                    t
                    for t in _trials(out)
                    if t.state == TrialState.RUNNING and "run_dir" in t.user_attrs
                ]
            except Exception:  # the first worker is still creating the tables
                running = []
            if running:
                first.kill()  # SIGKILL: no chance to tell the study anything
                killed = running[0]
        time.sleep(0.05)
    first.wait(timeout=30)
    assert killed is not None, first.stderr.read() if first.stderr else ""

    second = subprocess.run(
        _worker(out, 2), capture_output=True, text=True, check=False, timeout=300
    )
    assert 0 == second.returncode, second.stderr[-2000:]
    trials = _trials(out)
    complete = _complete(trials)
    assert 2 == len(complete)
    assert [TrialState.FAIL] == [t.state for t in trials if t.number == killed.number]
    # its parameters as stored (the snapshot taken while it ran may read the params table
    # before the worker's last suggestion landed, the user attributes after)
    (failed,) = [t for t in trials if t.number == killed.number]
    assert killed.params.items() <= failed.params.items()
    retried = [t for t in complete if t.system_attrs.get("failed_trial") is not None]
    assert [(killed.number, failed.params)] == [
        (t.system_attrs["failed_trial"], t.params) for t in retried
    ]
    # The killed trial's run folder was never completed under its final name.
    assert not (out / "trials" / f"{killed.number:04d}").exists()
    assert 2 == len({t.user_attrs["run_dir"] for t in complete})


def test_a_trial_without_heartbeat_is_failed_after_the_grace_period(
    tmp_path: Path,
) -> None:
    """A trial whose worker died before its first heartbeat does not block the study."""
    import optuna
    from optuna.trial import TrialState

    out = tmp_path / "sweep"
    out.mkdir()
    study = optuna.create_study(
        study_name=STUDY, storage=f"sqlite:///{out}/study.db", direction="maximize"
    )
    orphan = study.ask()  # RUNNING, never a heartbeat: like a worker killed at once
    done = subprocess.run(
        _worker(out, 2), capture_output=True, text=True, check=False, timeout=300
    )
    assert 0 == done.returncode, done.stderr[-2000:]
    trials = _trials(out)
    assert TrialState.FAIL == trials[orphan.number].state
    assert 2 == len(_complete(trials))


def test_a_worker_of_another_sweep_is_refused(tmp_path: Path) -> None:
    """A worker whose train overrides differ from the study's is refused in one line."""
    import optuna

    out = tmp_path / "sweep"
    out.mkdir()
    study = optuna.create_study(
        study_name=STUDY, storage=f"sqlite:///{out}/study.db", direction="maximize"
    )
    study.set_user_attr("slipkit_sweep", {"train_overrides": ["experiment=other"]})
    done = subprocess.run(_worker(out, 1), capture_output=True, text=True, check=False)
    assert 2 == done.returncode
    assert 1 == len(done.stderr.splitlines()), done.stderr
    assert "was started with train_overrides=['experiment=other']" in done.stderr
    assert [] == study.get_trials()


def test_a_worker_whose_runs_give_no_score_stops(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Trials without a finite validation score fail; three in a row stop the worker."""
    from hydra import compose, initialize_config_dir
    from optuna.trial import TrialState

    import slipkit.train.commands as commands
    from slipkit import config_dir
    from slipkit.train.optuna_sweep import sweep_main

    monkeypatch.setattr(commands, "train_main", lambda cfg: float("nan"))
    out = tmp_path / "sweep"
    given = [*TINY, "search=tactip_svm", "n_trials=5", f"out={out}"]
    with initialize_config_dir(config_dir=str(config_dir()), version_base="1.3"):
        cfg = compose(config_name="sweep", overrides=given)
        with pytest.raises(SlipkitError, match=r"trials \[0, 1, 2\] in a row gave no"):
            sweep_main(cfg, given)
    assert [TrialState.FAIL] * 3 == [t.state for t in _trials(out)]


def test_search_space_is_read_from_config() -> None:
    """configs/search/tactip_svm.yaml, with a command-line change, becomes the study's space."""
    from hydra import compose, initialize_config_dir
    from optuna.distributions import FloatDistribution

    from slipkit import config_dir

    with initialize_config_dir(config_dir=str(config_dir()), version_base="1.3"):
        cfg = compose(
            config_name="sweep",
            overrides=["search=tactip_svm", "search.params.model.C.high=100"],
        )
    expected = {
        "model.C": FloatDistribution(1.0, 100.0, log=True),
        "model.gamma": FloatDistribution(1e-5, 1e-1, log=True),
    }
    assert expected == read_space(cfg.search.params)


@pytest.mark.parametrize(
    ("spec", "message"),
    [
        ({"type": "normal", "low": 1, "high": 2}, r"model\.C\.type=normal: expected"),
        ({"type": "float", "low": 1}, r"model\.C: a float parameter needs high"),
        ({"type": "float", "low": 2, "high": 1}, r"model\.C: low=2 must be below"),
        ({"type": "float", "low": 0, "high": 1, "log": True}, r"model\.C: .*log"),
        ({"type": "int", "low": 1, "high": 4, "lo": 0}, r"model\.C\.lo: not a field"),
        ({"type": "categorical", "choices": []}, r"model\.C\.choices: expected a non"),
        ({"type": "float", "low": "a", "high": 1}, r"model\.C\.low=a: expected a num"),
    ],
)
def test_bad_space_names_the_parameter(spec: dict[str, Any], message: str) -> None:
    """A bad parameter spec is refused naming the parameter and field at fault."""
    with pytest.raises(SlipkitError, match=message):
        read_space({"model.C": spec})


def test_bad_space_is_a_one_line_cli_error(tmp_path: Path) -> None:
    """`slipkit sweep` with a bad space exits 2 with one line naming it; no study is made."""
    cmd = _worker(tmp_path / "sweep", 2, "search.params.model.C.low=-1")
    done = subprocess.run(cmd, capture_output=True, text=True, check=False)
    assert 2 == done.returncode
    lines = done.stderr.splitlines()
    assert 1 == len(lines), done.stderr
    assert lines[0].startswith("slipkit sweep: error: search.params.model.C:")
    assert not (tmp_path / "sweep").exists()


def test_a_key_the_train_config_lacks_is_refused(tmp_path: Path) -> None:
    """A search key that is not in the experiment's train config fails before any trial."""
    cmd = _worker(
        tmp_path / "sweep",
        2,
        "+search.params.model.CC={type:float,low:1,high:2}",
    )
    done = subprocess.run(cmd, capture_output=True, text=True, check=False)
    assert 2 == done.returncode
    assert "search.params.model.CC: the train config" in done.stderr
    assert not (tmp_path / "sweep").exists()


def test_missing_search_is_refused() -> None:
    """`slipkit sweep` without search= says it is required."""
    cmd = [sys.executable, "-c", "from slipkit.cli import main; main()", "sweep"]
    done = subprocess.run(cmd, capture_output=True, text=True, check=False)
    assert (
        2,
        "slipkit sweep: error: search=...: missing; this option is required",
    ) == (
        done.returncode,
        done.stderr.strip(),
    )


@pytest.mark.parametrize(
    "value", [1e-05, 686.6, 3, True, None, "rbf", "two words", "it's", "null"]
)
def test_override_reads_back_as_the_same_value(value: Any) -> None:
    """A trial's parameter goes to Hydra as an override that parses back to the value."""
    from hydra.core.override_parser.overrides_parser import OverridesParser

    parsed = OverridesParser.create().parse_override(override("model.x", value))
    assert value == parsed.value()


def test_train_overrides_leave_out_the_sweeps_own_options() -> None:
    """Only train overrides reach the trials, not search= or the study's options."""
    given = [
        "experiment=x",
        "search=y",
        "search.params.a.low=1",
        "n_trials=3",
        "seed=2",
    ]
    assert ["experiment=x", "seed=2"] == train_overrides(given)
