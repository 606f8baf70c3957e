"""``slipkit export``: every learned family -> a bundle the runtime loads and decides with as the estimator."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hydra import compose, initialize_config_dir
from omegaconf import DictConfig

from slipkit import config_dir
from slipkit.errors import SlipkitError
from slipkit.export import export
from slipkit.export.commands import deploy_config, export_main
from slipkit.export.deploy import graph_inputs, slip_decisions
from slipkit.export.parity import estimator_score
from slipkit.families.biotac.export import force as _force  # noqa: F401  (registers the force exporters)
from slipkit.runtime import StreamLoop, load_bundle
from slipkit.train.commands import train_main
from slipkit.train.runs import read_run

FORCE = [
    "experiment=biotac_force",
    "~task.compare",
    "dataset.n_trials=5",
    "scene.model.duration_s=8",
    "task.block_s=4",
]
WINDOWS = [
    "experiment=biotac_slip_type",
    "~task.compare",
    "dataset.n_trials=10",
    "task.window=10",
    "task.sweep=[]",
    "task.first_frame_control=false",
    "task.dynamics=null",
    "model.max_epochs=3",
]
#: family -> (train overrides, exporter options the deployer passes)
FAMILIES: dict[str, tuple[list[str], dict[str, Any]]] = {
    "tactip_svm": (
        ["experiment=tactip_svm", "dataset.n_trials=4"],
        {"with_features": True},
    ),
    "force_normals": ([*FORCE, "model=force_normals"], {}),
    "force_lwr": ([*FORCE, "model=force_lwr", "model.n_fields=6"], {}),
    "force_mlp": ([*FORCE, "model=force_mlp3", "model.max_epochs=4"], {}),
    "window_mlp": (WINDOWS, {}),
    "window_cnn": ([*WINDOWS, "model=window_cnn", "task.mode=window"], {}),
}


def _compose(name: str, overrides: list[str]) -> DictConfig:
    with initialize_config_dir(config_dir=str(config_dir()), version_base="1.3"):
        return compose(config_name=name, overrides=overrides)


def _export_cfg(run: Path, out: Path, *extra: str) -> DictConfig:
    return _compose(
        "export", [f"run={run}", f"out={out}", "choose_session=false", *extra]
    )


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """One tiny trained run per learned family (module-scoped: trained once)."""
    import torch

    torch.set_num_threads(1)
    root = tmp_path_factory.mktemp("runs")
    out = {}
    for family, (overrides, _) in FAMILIES.items():
        train_main(_compose("train", [*overrides, f"run_dir={root / family}"]))
        out[family] = root / family
    return out


def _python_vs_loop(bundle_dir: Path, family: str) -> tuple[Any, Any, Any, Any]:
    """(loop result, python slip decisions, python scores, decision ends) on the bundle's replay."""
    run_model = read_run(
        json.loads((bundle_dir / "manifest.json").read_text())["training"]["run"]
    ).model
    bundle = load_bundle(bundle_dir)
    m = bundle.manifest.raw
    graph = export(run_model, **FAMILIES[family][1])
    replay = np.load(bundle_dir / "replay.npz")
    frames, times = replay["frames"], replay["timestamps"]
    # a gap in the replay (trials of a bundle with stream state) starts a new
    # recording: each part is its own stream, as the loop reads it
    cuts = np.flatnonzero(np.diff(times) > 1.5 / m["frame"]["rate_hz"]) + 1
    parts, part_ends = [], []
    for a, z in zip(np.r_[0, cuts], np.r_[cuts, len(frames)], strict=True):
        x, e = graph_inputs(
            frames[a:z],
            m["frame"],
            m["preprocessing"],
            [int(s) for s in graph.input_shape[1:]],
            skip_nonfinite=True,
        )
        parts.append(x)
        part_ends.append(e + a)
    inputs, ends = np.concatenate(parts), np.concatenate(part_ends)
    ref = estimator_score(run_model, graph, inputs)
    py_slip = slip_decisions(ref, m["decision"], m.get("threshold"))
    loop = StreamLoop(bundle)
    for values, ts in zip(frames, times, strict=True):
        loop.step(values, float(ts))
    return loop.result(), py_slip, ref, ends


@pytest.mark.parametrize("family", sorted(FAMILIES))
def test_exported_bundle_decides_as_the_estimator(
    family: str, runs: dict[str, Path], tmp_path: Path
) -> None:
    """The bundle loads, and the runtime loop's decisions on its replay match the Python estimator's."""
    out = tmp_path / "bundle"
    printed = export_main(_export_cfg(runs[family], out))
    assert out == printed
    res, py_slip, ref, ends = _python_vs_loop(out, family)
    assert ends.tolist() == res.frame.tolist()
    agree = float(np.mean(py_slip == res.slip))
    assert agree >= 0.999
    m = load_bundle(out).manifest
    score = np.asarray(ref).reshape(len(ref), -1)
    if m.decision.rule == "threshold":
        col = score[:, m.decision.column]
        margin = np.abs(col - (m.decision.threshold or 0.0))
        bad = py_slip != res.slip
        assert bool(np.all(margin[bad] <= 1e-4 * max(1.0, np.abs(col).max())))
        np.testing.assert_allclose(res.score, col, rtol=1e-4, atol=1e-3)


def test_tactip_manifest_carries_slip_class_debounce_budget_and_features(
    runs: dict[str, Path], tmp_path: Path
) -> None:
    """The TacTip bundle: raw pins in, 'slip' positive, the debounce the run chose on
    validation, TacTip budget, parity and provenance."""
    out = tmp_path / "tactip"
    export_main(_export_cfg(runs["tactip_svm"], out))
    raw = json.loads((out / "manifest.json").read_text())
    chosen = json.loads((runs["tactip_svm"] / "metrics.json").read_text())
    assert ["pins"] == raw["frame"]["streams"]
    assert [2, 254] == [raw["frame"]["window"], raw["frame"]["shape"][0]]
    assert "slip" == raw["decision"]["positive"]
    assert chosen["operating_point"]["debounce_k"] == raw["debounce"]["k"]
    assert pytest.approx(1000.0 / 120.0 / 10) == raw["budget_ms"]["p99"]  # 120 Hz data
    assert "subtract" == raw["preprocessing"][0]["op"]
    assert raw["training"]["parity"]["passed"] is True
    info = json.loads((runs["tactip_svm"] / "run.json").read_text())
    assert info["dataset"]["fingerprint"] == raw["training"]["data_fingerprint"]


def test_force_bundle_takes_its_baseline_from_the_stream(
    runs: dict[str, Path], tmp_path: Path
) -> None:
    """A force bundle subtracts the median of the stream's first 10 frames and decides on fz, unclassed."""
    out = tmp_path / "force"
    export_main(_export_cfg(runs["force_normals"], out, "regression.threshold=1.5"))
    raw = json.loads((out / "manifest.json").read_text())
    assert [{"op": "baseline_first", "frames": 10, "hop": 1}] == raw["preprocessing"]
    assert 2 == raw["decision"]["column"]
    assert "classes" not in raw["decision"]
    assert 1.5 == raw["threshold"]
    assert pytest.approx(1000.0 / 300.0 / 10) == raw["budget_ms"]["p99"]  # 300 Hz data


def test_choose_session_writes_measured_options(
    runs: dict[str, Path], tmp_path: Path
) -> None:
    """With choose_session the manifest's session is one of the measured candidates."""
    out = tmp_path / "svm"
    cfg = _compose(
        "export",
        [
            f"run={runs['force_normals']}",
            f"out={out}",
            "session.rounds=1",
            "session.max_frames=50",
        ],
    )
    export_main(cfg)
    session = json.loads((out / "manifest.json").read_text())["session"]
    assert session["intra_op_num_threads"] in (1, 2)


def test_forced_parity_failure_writes_no_bundle(
    runs: dict[str, Path], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A graph that no longer matches its estimator fails the check and leaves no folder."""
    from onnx import numpy_helper

    import slipkit.export as export_pkg

    real = export_pkg.export

    def broken(est: Any, **kw: Any) -> Any:
        g = real(est, **kw)
        init = g.model.graph.initializer[-1]  # the offsets of the weighted normals
        init.CopyFrom(
            numpy_helper.from_array(numpy_helper.to_array(init) + 1.0, init.name)
        )
        return g

    monkeypatch.setattr(export_pkg, "export", broken)
    out = tmp_path / "broken"
    with pytest.raises(SlipkitError, match="parity check failed"):
        export_main(_export_cfg(runs["force_normals"], out))
    assert not out.exists()
    assert [] == list(tmp_path.iterdir())


def test_existing_bundle_is_refused_without_overwrite(
    runs: dict[str, Path], tmp_path: Path
) -> None:
    """Exporting onto an existing folder raises unless overwrite=true."""
    out = tmp_path / "b"
    out.mkdir()
    with pytest.raises(SlipkitError, match="already exists"):
        export_main(_export_cfg(runs["force_normals"], out))


def test_slipkit_run_cli_replays_the_bundle(
    runs: dict[str, Path], tmp_path: Path
) -> None:
    """`python -m slipkit.runtime.cli <bundle> --json` decides on every replay window, as the Python loop."""
    out = tmp_path / "w"
    export_main(_export_cfg(runs["window_mlp"], out))
    res, py_slip, _, _ = _python_vs_loop(out, "window_mlp")
    summary = tmp_path / "s.json"
    proc = subprocess.run(
        [sys.executable, "-m", "slipkit.runtime.cli", str(out), "--json", str(summary)],
        capture_output=True,
        text=True,
        check=False,
    )
    assert 0 == proc.returncode, proc.stderr
    got = json.loads(summary.read_text())
    assert len(res.slip) == got["decisions"]
    assert int(py_slip.sum()) == got["slip_decisions"]


@pytest.mark.parametrize(
    ("sensor", "period"),
    [
        ("tactip", 8.333),
        ("biotac_sp", 3.333),
        ("fsr", 0.5),
        ("sliptack", 1.0),
        ("davis", 10.0),
        ("gelsight", 40.0),
    ],
)
def test_budget_is_a_tenth_of_the_sensors_frame_period(
    sensor: str, period: float
) -> None:
    """The deploy config listing the sensor gives its frame period and a p99 budget of 10 % of it."""
    cfg = _compose("export", ["run=x"])
    assert {"frame_period": period, "p99": pytest.approx(period / 10)} == deploy_config(
        cfg, sensor
    )


def test_unknown_sensor_has_no_budget() -> None:
    """A sensor no configs/deploy file lists is a clear error."""
    with pytest.raises(SlipkitError, match="no configs/deploy"):
        deploy_config(_compose("export", ["run=x"]), "no_such_sensor")


def test_explicit_deploy_choice_overrides_the_sensor() -> None:
    """deploy=<name> picks that sensor's budget whatever the run's sensor is."""
    cfg = _compose("export", ["run=x", "deploy=fsr"])
    assert {"frame_period": 0.5, "p99": 0.05} == deploy_config(cfg, "tactip")


def test_task_without_deployer_is_a_clear_error() -> None:
    """A task class no deployer knows is refused with the list of deployable tasks."""
    from slipkit.export.deploy import deployer_for

    class Undeployable:  # DAVIS deploys since issue 16: any class no deployer knows
        pass

    with pytest.raises(SlipkitError, match="deployable tasks"):
        deployer_for(Undeployable())  # type: ignore[arg-type]


def test_replay_holds_a_trial_of_every_class_and_wiring_past_the_frame_cap() -> None:
    """Long trials of one class and wiring fill replay_max_frames; the other class and
    the other wiring still get their shortest trial each; a hard cap is never passed."""
    from slipkit.export.deploy import Deployment, HeldOutTrial

    def trial(i: int, n: int, label: str, group: str) -> HeldOutTrial:
        return HeldOutTrial(
            f"t{i}", np.zeros((n, 1)), np.arange(n) / 100.0, None, label, group
        )

    trials = [
        trial(0, 100, "slip", "falling"),
        trial(1, 100, "slip", "falling"),
        trial(2, 300, "no_slip", "falling"),
        trial(3, 250, "no_slip", "falling"),
        trial(4, 400, "slip", "rising"),
    ]
    dep = Deployment(
        frame={"rate_hz": 100.0},
        preprocessing=[],
        export_options={},
        positive="slip",
        debounce_k=1,
        trials=trials,
    )
    assert ["t0", "t1", "t3", "t4"] == [t.trial_id for t in dep.replay_trials(200)]
    dep.max_replay_frames = 500
    assert ["t0", "t1", "t3"] == [t.trial_id for t in dep.replay_trials(200)]


def test_failed_stream_parity_writes_no_bundle(
    runs: dict[str, Path], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A baseline_first bundle whose loop over the held-out stream disagrees: one
    SlipkitError naming the stream parity, and no bundle folder."""
    import slipkit.export.parity as parity

    real = parity.stream_parity

    def disagreeing(*args: Any, **kwargs: Any) -> dict[str, Any]:
        report = real(*args, **kwargs)
        assert report["passed"]  # the real check passes: only its verdict is changed
        return {**report, "agreement": 0.977, "n_disagree": 214, "passed": False}

    monkeypatch.setattr(parity, "stream_parity", disagreeing)
    out = tmp_path / "force"
    with pytest.raises(SlipkitError, match=r"stream parity failed .* 97\.700 %"):
        export_main(_export_cfg(runs["force_normals"], out))
    assert not out.exists()


def test_sign_key_writes_a_signature_the_runtime_checks(
    runs: dict[str, Path], tmp_path: Path
) -> None:
    """export sign_key=<file> writes manifest.hmac: the bundle loads with the key and
    is refused with another; a key file inside the bundle folder is refused first."""
    from slipkit.runtime import BundleError

    key = tmp_path / "lab.key"
    key.write_bytes(b"the lab's key")
    out = tmp_path / "signed"
    export_main(_export_cfg(runs["force_normals"], out, f"sign_key={key}"))
    assert load_bundle(out, key=key.read_bytes()).manifest.name == "signed"
    with pytest.raises(BundleError, match=r"manifest\.hmac"):
        load_bundle(out, key=b"another key")
    inside = tmp_path / "b2"
    with pytest.raises(SlipkitError, match=r"sign_key: .* is inside the bundle"):
        export_main(_export_cfg(runs["force_normals"], inside, f"sign_key={inside}/k"))
    assert not inside.exists()
