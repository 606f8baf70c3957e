"""Model selection inside one run: Optuna TPE search and group-aware validation.

A TPE sampler with a fixed seed proposes values; each is scored by group-aware
cross-validation (``GroupKFold``: frames of one trial, or grasps of one object, never
sit on both sides), so the search never looks at the test side. Optuna does the
optimisation; this module only maps a small config to it::

    {param: [low, high]}            # uniform float
    {param: [low, high, "log"]}     # log-uniform float
    {param: [low, high, "int"]}     # integer
    {param: {choices: [a, b, c]}}   # categorical

Every search is recorded in the run as a *selection* record
(:func:`selection_record`): the method, the CV, the scoring, the chosen parameters,
their validation score and every candidate's mean and standard deviation over the
folds. :func:`group_cv` scores one fixed estimator the same way, so a task without a
search still reports a validation score for ``slipkit sweep`` to optimise.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np
from sklearn.base import clone
from sklearn.metrics import get_scorer
from sklearn.model_selection import GroupKFold, cross_val_score

from slipkit.progress import progress_line

log = logging.getLogger("slipkit.search")

#: ``method`` of the selection records written by :func:`optuna_search`.
METHOD = "optuna-tpe"


def _progress(label: str, done: int, total: int, start: float, extra: str = "") -> None:
    """One line on stderr: what runs, i of n, elapsed and a linear ETA (s)."""
    elapsed = time.perf_counter() - start
    eta = elapsed / done * (total - done) if done else float("nan")
    line = (
        f"{label} {done}/{total} done, {elapsed:.0f} s elapsed, ETA {eta:.0f} s{extra}"
    )
    # stderr, not the log: slipkit's log goes to stdout and the run's train.log.
    progress_line(line)


def _check_groups(groups: np.ndarray, cv: int, unit: str) -> None:
    from slipkit.data.splits import SplitError

    n_groups = len(np.unique(groups))
    # GroupKFold needs >= 2 folds: one training trial cannot be cross-validated.
    if n_groups < max(cv, 2):
        raise SplitError(
            f"group CV ({cv} fold(s)) needs >= {max(cv, 2)} {unit}s on the training side; "
            f"got {n_groups} (more trials, or a smaller test side)"
        )


def group_cv(
    estimator: Any,
    X: np.ndarray,
    y: np.ndarray,
    groups: np.ndarray,
    *,
    cv: int = 3,
    scoring: str = "balanced_accuracy",
    unit: str = "trial",
    label: str = "validation",
) -> dict[str, Any]:
    """Score a fixed ``estimator`` by ``GroupKFold`` over ``groups`` (training side only).

    Returns ``{"cv": "group-kfold by <unit>", "k": cv, "scoring": scoring,
    scoring: mean, "std": s, "folds": [...]}``: the record a task without a search
    stores as ``metrics["validation"]``.
    """
    _check_groups(groups, cv, unit)
    splitter = GroupKFold(n_splits=cv)
    start = time.perf_counter()
    scores = []
    for i, (tr, te) in enumerate(splitter.split(X, y, groups)):
        model = clone(estimator).fit(X[tr], y[tr])
        scores.append(_score(model, X[te], y[te], scoring))
        _progress(f"{label}: fold", i + 1, cv, start)
    return {
        "cv": f"group-kfold by {unit}",
        "k": int(cv),
        "scoring": scoring,
        scoring: float(np.mean(scores)),
        "std": float(np.std(scores)),
        "folds": [float(s) for s in scores],
    }


def mean_leaves(dicts: Sequence[Mapping[str, Any]]) -> dict[str, Any]:
    """Per key, the NaN-aware mean of the numeric leaves of ``dicts`` (same layout):
    the fold average of a task's nested metrics."""
    out: dict[str, Any] = {}
    for key, first in dicts[0].items():
        values = [d.get(key) for d in dicts]
        if isinstance(first, Mapping):
            out[key] = mean_leaves([v for v in values if isinstance(v, Mapping)])
        elif isinstance(first, int | float) and not isinstance(first, bool):
            nums = np.asarray(
                [v for v in values if isinstance(v, int | float)], dtype=float
            )
            out[key] = float(np.nanmean(nums)) if np.isfinite(nums).any() else np.nan
    return out


def trial_cv(
    trial_ids: Sequence[str],
    fit_score: Any,
    *,
    cv: int = 3,
    label: str = "validation",
) -> dict[str, Any]:
    """Group CV by trial for tasks whose fit and scoring work on datasets.

    ``fit_score(train_ids, held_out_ids)`` fits on the first trials and returns the
    task's metrics dict on the second; the folds' metrics are averaged
    (:func:`mean_leaves`). ``k = min(cv, n_trials)``; fewer than 2 trials is a
    :class:`~slipkit.data.splits.SplitError`.
    """
    ids = np.asarray(list(trial_ids), dtype=object)
    k = min(int(cv), len(ids))
    _check_groups(ids, k, "trial")  # SplitError (one line) below 2 trials
    start = time.perf_counter()
    folds = []
    for i, (a, b) in enumerate(GroupKFold(n_splits=k).split(ids, groups=ids)):
        folds.append(fit_score(list(ids[a]), list(ids[b])))
        _progress(f"{label}: fold", i + 1, k, start)
    return {"cv": "group-kfold by trial", "k": k, **mean_leaves(folds)}


def _score(model: Any, X: np.ndarray, y: np.ndarray, scoring: str) -> float:
    return float(get_scorer(scoring)(model, X, y))


def _suggest(trial: Any, name: str, spec: Any) -> Any:
    if isinstance(spec, Mapping):
        if "choices" not in spec:
            raise ValueError(f"search space {name!r}: a mapping needs 'choices'")
        return trial.suggest_categorical(name, list(spec["choices"]))
    low, high = spec[0], spec[1]
    kind = spec[2] if len(spec) > 2 else "linear"
    if kind == "int":
        return trial.suggest_int(name, int(low), int(high))
    if kind not in ("log", "linear"):
        raise ValueError(
            f"search space {name!r}: scale {kind!r}; expected log, linear or int"
        )
    return trial.suggest_float(name, float(low), float(high), log=kind == "log")


def optuna_search(
    estimator: Any,
    X: np.ndarray,
    y: np.ndarray,
    groups: np.ndarray,
    *,
    space: Mapping[str, Any],
    n_trials: int,
    cv: int = 3,
    scoring: str = "balanced_accuracy",
    seed: int = 0,
    unit: str = "trial",
    label: str = "search",
    scorer: Callable[[Any, np.ndarray, np.ndarray], float] | None = None,
) -> tuple[dict[str, Any], float, list[dict[str, Any]]]:
    """Search ``space`` with Optuna TPE; return (best params, best CV score, history).

    Parameters
    ----------
    estimator : scikit-learn estimator
        Cloned for every candidate; the search never fits it in place.
    space : mapping
        ``{name: [low, high]}``, ``[low, high, "log"]``, ``[low, high, "int"]`` or
        ``{choices: [...]}`` (see the module docstring).
    n_trials : int
        Candidates evaluated (>= 1).
    cv : int
        Folds of ``GroupKFold`` over ``groups``.
    scoring : str
        A scikit-learn scorer name, maximised.
    seed : int
        Seed of the TPE sampler: the same inputs give the same search.
    unit : str
        What one group is (``trial``, ``object``): for messages and the record.
    label : str
        What is searched, shown in the progress lines on stderr.
    scorer : callable, optional
        ``scorer(estimator, X, y)`` used instead of the scikit-learn scorer named
        ``scoring`` (which then only names it in messages and records).

    Returns
    -------
    best : dict
        The chosen parameters.
    best_score : float
        Their mean validation score over the folds.
    history : list of dict
        Per candidate: ``number``, ``value`` (mean), ``std``, ``folds`` and the
        parameters (flat, for tables), in the order they were tried.
    """
    import optuna

    if n_trials < 1:
        raise ValueError(f"n_trials must be >= 1; got {n_trials}")
    _check_groups(groups, cv, unit)
    optuna.logging.set_verbosity(optuna.logging.WARNING)
    splitter = GroupKFold(n_splits=cv)
    start = time.perf_counter()

    def objective(trial: Any) -> float:
        params = {name: _suggest(trial, name, spec) for name, spec in space.items()}
        model = clone(estimator).set_params(**params)
        scores = cross_val_score(
            model,
            X,
            y,
            groups=groups,
            cv=splitter,
            scoring=scoring if scorer is None else scorer,
        )
        trial.set_user_attr("std", float(np.std(scores)))
        trial.set_user_attr("folds", [float(s) for s in scores])
        mean = float(np.mean(scores))
        _progress(
            f"{label}: candidate",
            trial.number + 1,
            int(n_trials),
            start,
            f" ({cv} folds by {unit} each; this one {scoring} {mean:.4f})",
        )
        return mean

    study = optuna.create_study(
        direction="maximize", sampler=optuna.samplers.TPESampler(seed=seed)
    )
    study.optimize(objective, n_trials=int(n_trials))
    history = [
        {
            "number": t.number,
            "value": t.value,
            "std": t.user_attrs.get("std"),
            "folds": t.user_attrs.get("folds"),
            **t.params,
        }
        for t in study.trials
    ]
    log.info(
        "%s: best %s = %.4f at %s", label, scoring, study.best_value, study.best_params
    )
    return dict(study.best_params), float(study.best_value), history


def selection_record(
    best: Mapping[str, Any],
    best_score: float,
    history: Sequence[Mapping[str, Any]],
    *,
    cv: int,
    scoring: str,
    unit: str = "trial",
    method: str = METHOD,
) -> dict[str, Any]:
    """The ``metrics["selection"]`` record of one search (see the module docstring)."""
    skip = {"number", "value", "std", "folds"}
    return {
        "method": method,
        "cv": f"group-kfold by {unit}",
        "k": int(cv),
        "scoring": scoring,
        "best": dict(best),
        "best_score": float(best_score),
        "candidates": [
            {
                "params": {k: v for k, v in h.items() if k not in skip},
                "mean": h["value"],
                "std": h.get("std"),
            }
            for h in history
        ],
    }


def format_best(record: Mapping[str, Any]) -> str:
    """One line: the chosen parameters and their validation score."""
    params = ", ".join(
        f"{k}={v:.4g}" if isinstance(v, float) else f"{k}={v}"
        for k, v in record["best"].items()
    )
    return (
        f"selected on validation ({record['cv']}, k={record['k']}, "
        f"{record['scoring']} {record['best_score']:.4f} over "
        f"{len(record['candidates'])} candidates): {params}"
    )


__all__ = [
    "METHOD",
    "format_best",
    "group_cv",
    "mean_leaves",
    "optuna_search",
    "selection_record",
    "trial_cv",
]
