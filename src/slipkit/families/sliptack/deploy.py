"""The SlipTack speed task's deployer (registered with :mod:`slipkit.export.deploy`)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from slipkit.data.dataset import Dataset
from slipkit.errors import SlipkitError
from slipkit.export.deploy import (
    Deployment,
    _frame,
    _rate,
    register_deployer,
    run_metrics,
    trial_frames,
)
from slipkit.train.runs import Run
from slipkit.train.task import Task


def _deploy_sliptack_speed(
    task: Task, run: Run, dataset: Dataset, options: Mapping[str, Any]
) -> Deployment:
    """``SlipTackSpeed``: raw nib samples, the whole speed estimator in the graph.

    Frame = one sample of ``task.stream`` / ``task.column``; window and hop are the
    estimator's (``window``, ``hop``: the graph is called at the batch estimator's
    estimation instants). The run saves one estimator per training material plus
    ``"*"`` (all training trials, the configured friction); a gripper does not know
    the material, so ``"*"`` is deployed. A speed has no slip class: the decision is
    :class:`slipkit.families.sliptack.export.detector.SpeedSlipDetector`'s ``speed >= threshold`` with
    the threshold from the export config's ``regression.threshold`` (mm/s; 0: slip
    whenever a stick-slip frequency is found), class ``"1"``.
    """
    from slipkit.families.sliptack.export.detector import SpeedSlipDetector
    from slipkit.families.sliptack.export.speed import (
        incremental_problem,
        sliding_spectrum_step,
    )
    from slipkit.families.sliptack.task import DEFAULT, SlipTackSpeed, _split

    assert isinstance(task, SlipTackSpeed)
    models = run.model
    est = models.get(DEFAULT) if isinstance(models, Mapping) else models
    if est is None:
        raise SlipkitError(
            f"run {run.path}: the SlipTack speed model has no {DEFAULT!r} entry "
            f"(has {sorted(models)})"
        )
    stream = task.stream
    rate = _rate(dataset, stream, options)
    if abs(rate - float(est.rate_hz)) > 1e-9 * rate:
        raise SlipkitError(
            f"stream {stream!r} runs at {rate:g} Hz but the estimator's rate_hz is "
            f"{float(est.rate_hz):g} Hz"
        )
    reg = dict(options.get("regression") or {})
    threshold = float(reg.get("threshold") or 0.0)
    steps: list[dict[str, Any]] = []
    export_options: dict[str, Any] = {}
    from slipkit.families.sliptack.spectral import SpectralSpeedRegressor

    if isinstance(est, SpectralSpeedRegressor):  # learned: export/spectral.py's graph
        from slipkit.families.sliptack.export.spectral import SpectralSlipDetector

        detector = SpectralSlipDetector(speed=est, threshold=threshold).fit()
        holds = f"SpectralSpeedRegressor ({est.model}, material '*')"
    else:
        detector = SpeedSlipDetector(speed=est, threshold=threshold).fit()
        holds = f"StickSlipSpeed ({est.form} form, material '*')"
        # regression.incremental: the spectrum updated per hop by the runtime op
        # sliding_spectrum, the graph reading it (export/sliptack.py, Incremental);
        # else (default: measured faster, docs/deploy.md) the whole window per call
        why = (
            incremental_problem(est)
            if reg.get("incremental", False)
            else "regression.incremental=false"
        )
        if why is None:
            steps = [sliding_spectrum_step(est)]
            export_options = {"incremental": True}
            holds += "; spectrum per hop by the runtime op sliding_spectrum"
        elif reg.get("prepare", True) and int(est.window) >= 2:
            # regression.prepare (default): steps 1-2 on the frame before each
            # decision by prepare.onnx, the decision frame adding its sample's share
            export_options = {"prepare": True}
            holds += (
                f"; whole-window spectrum ({why}) prepared on the frame before each "
                "decision (prepare.onnx; regression.prepare=true)"
            )
        else:
            holds += f"; whole-window spectrum per call ({why})"
    split = run_metrics(run).get("split", {})
    if split.get("test"):
        test_ids = list(split["test"])
    else:  # the task's own split (stratified by material when it can be), the run's seed
        seed = int(run.config.get("seed", 0))
        test_ids = list(_split(dataset, task.test_size, seed, task.group).test)
    channels = [task.column]
    return Deployment(
        frame=_frame([stream], channels, int(est.window), int(est.hop), rate),
        preprocessing=steps,
        export_options=export_options,
        positive="1",
        debounce_k=int(options.get("debounce_k") or 1),
        trials=trial_frames(dataset, test_ids, stream, channels),
        notes=[
            f"raw {stream!r} samples ({task.column}, mm) at {rate:g} Hz; the graph holds "
            f"{holds} on the last {int(est.window)} "
            f"samples, called every {int(est.hop)} samples",
            f"decision: speed >= {threshold:g} mm/s (regression.threshold; no estimate: "
            "no slip)",
        ],
        detector=True,
        model=detector,  # the run saved a dict of per-material estimators
    )


def _register_sliptack() -> None:
    from slipkit.families.sliptack.task import SlipTackSpeed

    register_deployer(SlipTackSpeed, _deploy_sliptack_speed)


_register_sliptack()
