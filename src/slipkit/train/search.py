"""Bayesian optimisation of an estimator's hyper-parameters inside one run (Optuna).

A TPE sampler with a fixed seed proposes values; each is scored by group-aware
cross-validation (``GroupKFold``: frames of one trial never sit on both sides), so
the search never looks at the test side. Optuna does the optimisation; this module
only maps a small config (``{param: [low, high, "log"|"linear"]}``) to it.
"""

from __future__ import annotations

import logging
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from sklearn.base import clone
from sklearn.model_selection import GroupKFold, cross_val_score

log = logging.getLogger("slipkit.search")


def optuna_search(
    estimator: Any,
    X: np.ndarray,
    y: np.ndarray,
    groups: np.ndarray,
    *,
    space: Mapping[str, Sequence[Any]],
    n_trials: int,
    cv: int = 3,
    scoring: str = "balanced_accuracy",
    seed: int = 0,
) -> tuple[dict[str, float], float, list[dict[str, Any]]]:
    """Search ``space`` with Optuna TPE; return (best params, best CV score, history).

    Parameters
    ----------
    estimator : scikit-learn estimator
        Cloned for every candidate; the search never fits it in place.
    space : mapping
        ``{name: [low, high]}`` or ``[low, high, "log"]`` (log-uniform).
    n_trials : int
        Candidates evaluated (>= 1).
    cv : int
        Folds of ``GroupKFold`` over ``groups``.
    scoring : str
        A scikit-learn scorer name, maximised.
    seed : int
        Seed of the TPE sampler: the same inputs give the same search.
    """
    # optuna 2.10 imports alembic, which logs its plugin setup at INFO to our stdout log.
    logging.getLogger("alembic").setLevel(logging.WARNING)
    import optuna

    if n_trials < 1:
        raise ValueError(f"n_trials must be >= 1; got {n_trials}")
    n_groups = len(np.unique(groups))
    if n_groups < cv:
        raise ValueError(
            f"{cv}-fold group CV needs >= {cv} trials on the training side; got {n_groups}"
        )
    optuna.logging.set_verbosity(optuna.logging.WARNING)
    splitter = GroupKFold(n_splits=cv)

    def objective(trial: Any) -> float:
        params = {}
        for name, spec in space.items():
            low, high = float(spec[0]), float(spec[1])
            log_scale = len(spec) > 2 and spec[2] == "log"
            params[name] = trial.suggest_float(name, low, high, log=log_scale)
        model = clone(estimator).set_params(**params)
        scores = cross_val_score(
            model, X, y, groups=groups, cv=splitter, scoring=scoring
        )
        return float(np.mean(scores))

    study = optuna.create_study(
        direction="maximize", sampler=optuna.samplers.TPESampler(seed=seed)
    )
    study.optimize(objective, n_trials=int(n_trials))
    history = [{"number": t.number, "value": t.value, **t.params} for t in study.trials]
    log.info(
        "optuna: best %s = %.4f at %s", scoring, study.best_value, study.best_params
    )
    return dict(study.best_params), float(study.best_value), history
