"""Choose among candidate pipelines by group-aware cross-validation, as one estimator.

:class:`CandidateSearch` is given named candidate estimators (e.g. a statistics +
logistic-regression Pipeline, an RBF SVM, the window networks) and a small grid of
hyper-parameters for each. ``fit(X, y, groups=...)`` scores every (candidate,
parameters) pair by leave-one-group-out cross-validation on the rows it is given --
with ``groups`` the object of each window, every validation fold is an object the
candidate never saw --, keeps the best mean score, and refits that one on all rows.
Test data never reaches it: the task fits one search per outer fold, on that fold's
training objects only (nested cross-validation).

The loop is written here rather than with ``GridSearchCV`` because the candidates
are different estimators (not one Pipeline's parameters), the progress (candidate j
of n, fold i of k, elapsed and ETA) goes to stderr through tqdm, and ``subsample``
thins the heavily overlapping windows of the inner fits; the parts are scikit-learn's
(``ParameterGrid``, ``LeaveOneGroupOut`` / ``GroupKFold``, ``get_scorer``, ``clone``).

``selection_`` is the record the task writes to ``metrics["selection"]`` (the same
shape as the in-run Optuna search's).
"""

from __future__ import annotations

import inspect
import sys
import time
from collections.abc import Mapping
from numbers import Integral
from typing import Any, ClassVar

import numpy as np
from numpy.typing import ArrayLike, NDArray
from sklearn.base import BaseEstimator, ClassifierMixin, clone
from sklearn.metrics import get_scorer
from sklearn.model_selection import GroupKFold, LeaveOneGroupOut, ParameterGrid
from sklearn.utils._param_validation import Interval, StrOptions
from sklearn.utils.parallel import Parallel, delayed
from sklearn.utils.validation import check_is_fitted

__all__ = ["CandidateSearch", "fit_with_groups"]


def fit_with_groups(model: Any, X: Any, y: Any, groups: Any) -> Any:
    """``model.fit``, passing ``groups`` when the model's ``fit`` takes them."""
    if "groups" in inspect.signature(model.fit).parameters:
        return model.fit(X, y, groups=groups)
    return model.fit(X, y)


def _plain(value: Any) -> Any:
    """A JSON-friendly form of a hyper-parameter value."""
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, (str, int, float, bool)) or value is None:
        return value
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    return repr(value)


def _fold_score(
    base: Any,
    X: NDArray[Any],
    y: NDArray[Any],
    g: NDArray[Any],
    tr: NDArray[np.intp],
    va: NDArray[np.intp],
    scorer: Any,
) -> float:
    """Fit a clone of ``base`` on rows ``tr``, score it on rows ``va``."""
    est = clone(base)
    fit_with_groups(est, X[tr], y[tr], g[tr])
    return float(scorer(est, X[va], y[va]))


class CandidateSearch(ClassifierMixin, BaseEstimator):
    """The best of several candidate classifiers by group-aware cross-validation.

    Parameters
    ----------
    candidates : mapping of str to estimator
        Named candidates, in the order they are tried (ties go to the earlier one:
        list the cheaper first).
    grids : mapping of str to mapping or list of mappings, optional
        ``{name: {param: [values]}}``: each candidate's grid (``ParameterGrid``
        syntax, a list of mappings for several sub-grids; nested names such as
        ``clf__C`` for Pipelines). A candidate without a grid is tried with its own
        parameters.
    cv : "leave-one-group-out" or int
        Leave one group out, or ``GroupKFold`` with this many folds.
    scoring : str
        A scikit-learn scorer name, maximised (``balanced_accuracy``).
    subsample : int
        Inner fits and scores use every ``subsample``-th row (consecutive windows
        of a trial overlap, so thinning loses little); the refit uses all rows.
    verbose : bool
        A tqdm progress bar on stderr (candidate, fold, elapsed, ETA).
    n_jobs : int or None
        Inner folds of one candidate fitted in parallel (joblib processes); None or
        1 fits them one after the other (the bar then moves per fold, else per
        candidate).

    Attributes
    ----------
    best_name_ : str
        Name of the chosen candidate.
    best_params_ : dict
        Its grid parameters.
    best_score_ : float
        Its mean validation score.
    best_estimator_ : estimator
        The chosen candidate refitted on every row.
    cv_results_ : list of dict
        ``name``, ``params``, ``mean``, ``std``, ``scores`` and ``fit_s`` of every pair.
    selection_ : dict
        ``method``, ``cv``, ``scoring``, ``best``, ``best_score``, ``candidates``.
    classes_ : ndarray
        Class labels of the chosen model.
    n_features_in_ : int
        Inputs per row.
    """

    _parameter_constraints: ClassVar[dict[str, list[Any]]] = {
        "candidates": [Mapping],
        "grids": [Mapping, None],  # values: a mapping or a list of mappings
        "cv": [
            StrOptions({"leave-one-group-out"}),
            Interval(Integral, 2, None, closed="left"),
        ],
        "scoring": [str],
        "subsample": [Interval(Integral, 1, None, closed="left")],
        "verbose": ["boolean"],
        "n_jobs": [Interval(Integral, 1, None, closed="left"), None],
    }

    def __init__(
        self,
        *,
        candidates: Mapping[str, Any],
        grids: Mapping[str, Mapping[str, Any]] | None = None,
        cv: str | int = "leave-one-group-out",
        scoring: str = "balanced_accuracy",
        subsample: int = 1,
        verbose: bool = True,
        n_jobs: int | None = None,
    ) -> None:
        self.candidates = candidates
        self.grids = grids
        self.cv = cv
        self.scoring = scoring
        self.subsample = subsample
        self.verbose = verbose
        self.n_jobs = n_jobs

    def _pairs(self) -> list[tuple[str, dict[str, Any]]]:
        grids = dict(self.grids or {})
        unknown = sorted(set(grids) - set(self.candidates))
        if unknown:
            raise ValueError(
                f"grids name candidates that do not exist: {unknown}; candidates: "
                f"{list(self.candidates)}"
            )
        pairs = []
        for name in self.candidates:
            grid = grids.get(name)
            # a mapping is one grid; a list of mappings is several (ParameterGrid's forms)
            spec: Any = [dict(g) for g in grid] if isinstance(grid, list) else grid
            params = list(ParameterGrid(spec)) if grid else [{}]
            pairs += [(str(name), dict(p)) for p in params]
        return pairs

    def fit(self, X: ArrayLike, y: ArrayLike, *, groups: ArrayLike) -> CandidateSearch:
        """Score every candidate by group CV on these rows, refit the best on all.

        Parameters
        ----------
        X : array_like of shape (n_rows, n_features)
        y : array_like of shape (n_rows,)
        groups : array_like of shape (n_rows,)
            Group of each row (the object): a validation fold is whole groups.

        Returns
        -------
        self
        """
        self._validate_params()
        if not self.candidates:
            raise ValueError("candidates must name at least one estimator")
        X = np.asarray(X)
        y = np.asarray(y)
        g = np.asarray(groups)
        n_groups = len(np.unique(g))
        splitter: Any = (
            LeaveOneGroupOut()
            if self.cv == "leave-one-group-out"
            else GroupKFold(n_splits=int(self.cv))
        )
        need = 2 if self.cv == "leave-one-group-out" else int(self.cv)
        if n_groups < need:
            raise ValueError(
                f"group cross-validation ({self.cv}) needs >= {need} groups; got {n_groups}"
            )
        rows = np.arange(len(y))[:: self.subsample]
        splits = list(splitter.split(rows, y[rows], g[rows]))
        pairs = self._pairs()
        scorer = get_scorer(self.scoring)
        from tqdm.auto import tqdm

        bar = tqdm(
            total=len(pairs) * len(splits),
            desc="select",
            file=sys.stderr,
            disable=not self.verbose,
            leave=False,
            mininterval=1.0,
        )
        results: list[dict[str, Any]] = []
        try:
            for j, (name, params) in enumerate(pairs, 1):
                t0 = time.perf_counter()
                base = clone(self.candidates[name]).set_params(**params)
                if self.n_jobs is not None and self.n_jobs > 1:
                    bar.set_postfix_str(
                        f"candidate {j}/{len(pairs)} {name}, {len(splits)} folds "
                        f"in {self.n_jobs} jobs",
                        refresh=False,
                    )
                    scores = Parallel(n_jobs=self.n_jobs)(
                        delayed(_fold_score)(base, X, y, g, rows[tr], rows[va], scorer)
                        for tr, va in splits
                    )
                    bar.update(len(splits))
                else:
                    scores = []
                    for i, (tr, va) in enumerate(splits, 1):
                        bar.set_postfix_str(
                            f"candidate {j}/{len(pairs)} {name}, fold {i}/{len(splits)}",
                            refresh=False,
                        )
                        scores.append(
                            _fold_score(base, X, y, g, rows[tr], rows[va], scorer)
                        )
                        bar.update(1)
                results.append(
                    {
                        "name": name,
                        "params": {k: _plain(v) for k, v in params.items()},
                        "mean": float(np.mean(scores)),
                        "std": float(np.std(scores)),
                        "scores": scores,
                        "fit_s": time.perf_counter() - t0,
                    }
                )
        finally:
            bar.close()
        best = int(np.argmax([r["mean"] for r in results]))  # first of equals
        name, params = pairs[best]
        self.cv_results_ = results
        self.best_name_ = name
        self.best_params_ = params
        self.best_score_ = results[best]["mean"]
        self.best_estimator_ = clone(self.candidates[name]).set_params(**params)
        fit_with_groups(self.best_estimator_, X, y, g)
        self.classes_ = np.asarray(self.best_estimator_.classes_)
        self.n_features_in_ = X.shape[1]
        for attr in ("n_parameters_", "flops_per_window_", "n_epochs_"):
            if hasattr(self.best_estimator_, attr):
                setattr(self, attr, getattr(self.best_estimator_, attr))
        self.selection_ = {
            "method": "grid search over candidates",
            "cv": "leave-one-object-out"
            if self.cv == "leave-one-group-out"
            else f"{self.cv}-fold group k-fold",
            "scoring": self.scoring,
            "best": {"name": name, **results[best]["params"]},
            "best_score": self.best_score_,
            "candidates": [
                {k: r[k] for k in ("name", "params", "mean", "std")} for r in results
            ],
            "n_groups": n_groups,
            "subsample": self.subsample,
        }
        return self

    def predict_proba(self, X: ArrayLike) -> NDArray[Any]:
        """The chosen model's class probabilities (columns in ``classes_`` order)."""
        check_is_fitted(self)
        return np.asarray(self.best_estimator_.predict_proba(X))

    def predict(self, X: ArrayLike) -> NDArray[Any]:
        """The chosen model's class of every row."""
        check_is_fitted(self)
        return np.asarray(self.best_estimator_.predict(X))
