"""TacTip slip detection from pin velocities (James, Pestell, Lepora 2018).

Frames are labelled 'slip' for the first ``n_slip`` velocity frames after the onset
(None: every frame after it), runs are split in halves (train / test, by trial), the
SVM's C and gamma can be tuned by Bayesian optimisation on the training half, and the
online rule (``debounce_k`` consecutive slip frames) gives each test run a detection
delay in frames and ms.

With ``operating_point`` the debounce ``k`` is the deployed operating point, chosen on
validation trials: out-of-fold decisions of the training frames (group k-fold by the
dataset's ``object`` when the training half holds two objects or more, else by
trial) are turned into trial events (:mod:`slipkit.evaluate.events`: an alarm at the
``k``-th consecutive slip frame, early alarms, delay from the onset) for each
candidate ``k``, and the ``k`` of lowest mean cost within the limits is kept (the
fitted model carries it as ``debounce_k_``). The test half is scored once, at it.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from numpy.typing import NDArray
from sklearn.base import ClassifierMixin as _ClassifierMixin
from sklearn.base import clone
from sklearn.model_selection import GroupKFold, cross_val_predict

from slipkit.data.dataset import Dataset
from slipkit.data.splits import split_by_trial
from slipkit.errors import SlipkitError
from slipkit.evaluate.events import (
    Cost,
    OperatingPoint,
    TrialTruth,
    choose_operating_point,
    evaluate_point,
    events_table,
    parse_operating_point,
    slipped_of,
)
from slipkit.evaluate.metrics import classification_metrics, delay_summary
from slipkit.families.tactip.features import DatasetFeatures, dataset_features
from slipkit.features.pins import SLIP, STATIC, VARIANTS, Variant
from slipkit.models.online import detection_delay, first_detection
from slipkit.train.search import (
    format_best,
    group_cv,
    optuna_search,
    selection_record,
)
from slipkit.train.task import Task, TaskResult, analytic_estimators

log = logging.getLogger("slipkit.tactip")
LABELS = (STATIC, SLIP)


class TacTipFrames(Task):
    """Per-frame slip / static classification of TacTip pin velocities.

    Parameters
    ----------
    variant : {"dr_dtheta", "dr", "dtheta"}
        Features (254 or 127 for the paper's 127 pins).
    n_slip : int or None
        Velocity frames after the onset labelled 'slip' (paper: 4 best; None = all).
    test_size : float
        Fraction of trials held out (paper: half).
    debounce_k : int
        Consecutive slip frames before slip is declared online (paper: 2); with
        ``operating_point`` the fallback when no validation is possible.
    operating_point : mapping or None
        Choose ``k`` on validation trials among ``debounce`` by the ``cost`` within
        the limits (:func:`slipkit.evaluate.events.parse_operating_point`; the frame
        classifier's own decision is the threshold). None: ``debounce_k``.
    search : mapping or None
        In-run Bayesian optimisation: ``{n_trials, cv, scoring, space: {C: [lo, hi,
        "log"], gamma: [...]}}``; None or ``n_trials: 0`` keeps the model's parameters.
    cv : int
        Folds of the group CV (by trial, training side only) that gives the run's
        validation score when there is no search (with a search: ``search.cv``).
    scoring : str
        Scikit-learn scorer of that validation (with a search: ``search.scoring``);
        the run's objective is ``validation.<scoring>``.
    stream, label : str
        Pins stream and onset label names.
    """

    accepts = (_ClassifierMixin,)
    refuses = analytic_estimators()
    feeds = "fits a learned classifier on pin features of stream {stream}"

    objective = "validation.balanced_accuracy"
    direction = "maximize"

    def __init__(
        self,
        *,
        variant: Variant = "dr_dtheta",
        n_slip: int | None = 4,
        test_size: float = 0.5,
        debounce_k: int = 2,
        operating_point: Mapping[str, Any] | None = None,
        search: Mapping[str, Any] | None = None,
        cv: int = 3,
        scoring: str = "balanced_accuracy",
        stream: str = "pins",
        label: str = "slip_onset_s",
    ) -> None:
        if variant not in VARIANTS:
            raise SlipkitError(
                f"task.variant={variant}: expected one of {', '.join(VARIANTS)}"
            )
        self.variant = variant
        self.n_slip = n_slip
        self.test_size = test_size
        self.debounce_k = debounce_k
        self.operating_point = parse_operating_point(operating_point)
        self.search = search
        self.cv = cv
        self.scoring = scoring
        self.stream = stream
        self.label = label
        # The sweeper optimises a validation score of the training side, never test.
        self.objective = f"validation.{self._selection_scoring()}"

    # -- data -----------------------------------------------------------------
    def features(self, dataset: Dataset) -> DatasetFeatures:
        """(X, y, t, groups) of every velocity frame of ``dataset``."""
        return dataset_features(
            dataset,
            variant=self.variant,
            n_slip=self.n_slip,
            stream=self.stream,
            label=self.label,
        )

    def rate_hz(self, dataset: Dataset) -> float:
        spec = dataset.streams[self.stream]
        if spec.rate_hz is None:
            raise ValueError(f"stream {self.stream!r} has no frame rate")
        return float(spec.rate_hz)

    # -- fit / score ------------------------------------------------------------
    def _searching(self) -> bool:
        return int((self.search or {}).get("n_trials", 0)) > 0

    def _selection_scoring(self) -> str:
        if self._searching():
            return str((self.search or {}).get("scoring", "balanced_accuracy"))
        return str(self.scoring)

    def fit_model(
        self, model: Any, feats: DatasetFeatures, *, seed: int, validate: bool = True
    ) -> tuple[Any, dict[str, Any]]:
        """Fit ``model`` on ``feats`` (the training side) after model selection.

        With a search, Optuna picks the parameters by group CV by trial
        (``info["selection"]``, ``info["search"]``); without one and with
        ``validate``, the model's own parameters are scored by the same group CV.
        Either way ``info["validation"]`` holds the validation score of the fitted
        parameters. ``feats`` must not contain test frames.
        """
        info: dict[str, Any] = {}
        search = dict(self.search or {})
        scoring = self._selection_scoring()
        if self._searching():
            cv = int(search.get("cv", 3))
            best, score, history = optuna_search(
                model,
                feats.X,
                feats.y,
                feats.groups,
                space=search["space"],
                n_trials=int(search["n_trials"]),
                cv=cv,
                scoring=scoring,
                seed=seed,
                label=f"TacTip SVM ({getattr(model, 'kernel', '?')}) search",
            )
            model.set_params(**best)
            info["search"] = {
                "best_params": best,
                "best_cv_score": score,
                "scoring": scoring,
                "history": history,
            }
            info["selection"] = selection_record(
                best, score, history, cv=cv, scoring=scoring
            )
            best_row = max(history, key=lambda h: h["value"])
            info["validation"] = {
                "cv": "group-kfold by trial",
                "k": cv,
                "scoring": scoring,
                scoring: score,
                "std": best_row.get("std"),
                "folds": best_row.get("folds"),
                "source": "selection (best candidate)",
            }
            log.info("%s", format_best(info["selection"]))
        elif validate:
            # Fewer training trials than folds: one trial per fold (leave-one-out).
            k = min(int(self.cv), len(np.unique(feats.groups)))
            if k < int(self.cv):
                log.warning("validation: %d training trials, %d folds", k, k)
            info["validation"] = group_cv(
                model,
                feats.X,
                feats.y,
                feats.groups,
                cv=k,
                scoring=scoring,
                label="TacTip SVM validation",
            )
        model.fit(feats.X, feats.y)
        info["params"] = _svm_params(model)
        return model, info

    def truths(
        self, dataset: Dataset, feats: DatasetFeatures
    ) -> tuple[list[TrialTruth], list[NDArray[np.intp]]]:
        """Each trial's truth on its velocity frames (times ``feats.t``) and its rows."""
        onsets = {
            tr.trial_id: (
                float(tr.labels.get(self.label, np.nan)),
                slipped_of(tr.labels, float(tr.labels.get(self.label, np.nan))),
            )
            for tr in dataset
        }
        truths, rows = [], []
        for tid in dict.fromkeys(feats.groups):
            idx = np.flatnonzero(feats.groups == tid)
            onset, slipped = onsets[str(tid)]
            truths.append(TrialTruth(str(tid), feats.t[idx], slipped, onset))
            rows.append(idx)
        return truths, rows

    def debounce_of(self, model: Any) -> int:
        """The deployed debounce: the model's chosen ``debounce_k_``, else the task's."""
        return int(getattr(model, "debounce_k_", self.debounce_k))

    def score(
        self,
        model: Any,
        dataset: Dataset,
        feats: DatasetFeatures,
        *,
        debounce_k: int | None = None,
    ) -> tuple[dict[str, Any], pd.DataFrame]:
        """Frame metrics, per-trial online detection and a per-frame predictions table.

        ``debounce_k`` (None: :meth:`debounce_of` the model) sets the online rule and
        the trial events (``operating_point``).
        """
        _check_pin_count(model, feats, self.variant)
        k = self.debounce_of(model) if debounce_k is None else int(debounce_k)
        pred = np.asarray(model.predict(feats.X))
        metrics = classification_metrics(feats.y, pred, LABELS)
        rate = self.rate_hz(dataset)
        delays: list[float] = []
        false_alarms = 0
        for tid in dict.fromkeys(feats.groups):
            rows = feats.groups == tid
            onset = np.flatnonzero(feats.y[rows] == SLIP)
            if len(onset) == 0:
                fired = first_detection(pred[rows], k)
                false_alarms += fired is not None
                continue
            d = detection_delay(pred[rows], int(onset[0]), k)
            delays.append(np.nan if d is None else float(d))
        metrics["detection"] = {
            "debounce_k": k,
            **delay_summary(delays, rate),
            "false_alarm_trials_without_slip": false_alarms,
        }
        truths, rows_of = self.truths(dataset, feats)
        summary, _ = evaluate_point(
            truths,
            [(pred[r] == SLIP).astype(np.float64) for r in rows_of],
            0.5,
            k,
            self.cost,
        )
        metrics["operating_point"] = {"threshold": math.nan, "debounce_k": k, **summary}
        table = pd.DataFrame(
            {"trial_id": feats.groups, "t": feats.t, "label": feats.y, "pred": pred}
        )
        return metrics, table

    @property
    def cost(self) -> Cost:
        """The trial events' cost weights (``operating_point.cost``)."""
        return (self.operating_point or {}).get("cost") or Cost()

    def choose_debounce(
        self, model: Any, train: Dataset, feats: DatasetFeatures
    ) -> tuple[OperatingPoint, str] | None:
        """The debounce ``k`` of lowest validation cost (None without ``operating_point``
        or with fewer than two training groups).

        Out-of-fold decisions of clones of the fitted ``model`` (its selected
        parameters) by group k-fold on the training frames: groups are the training
        trials' ``object`` when there are two or more, else the trials.
        """
        cfg = self.operating_point
        if cfg is None:
            return None
        groups: NDArray[Any] = feats.groups
        by = "trial"
        if "object" in train.trials.columns:
            obj = train.trials.set_index("trial_id")["object"].astype(str)
            by_obj = obj.loc[feats.groups.astype(str)].to_numpy()
            if len(set(by_obj)) >= 2:
                groups, by = by_obj, "object"
        k = min(int(self.cv), len(set(groups)))
        if k < 2:
            log.warning(
                "operating point: one training group, debounce %d kept", self.debounce_k
            )
            return None
        pred = cross_val_predict(
            clone(model), feats.X, feats.y, groups=groups, cv=GroupKFold(n_splits=k)
        )
        truths, rows = self.truths(train, feats)
        point = choose_operating_point(
            truths,
            [(np.asarray(pred)[r] == SLIP).astype(np.float64) for r in rows],
            thresholds=[0.5],
            debounce_ks=cfg["debounce"],
            cost=self.cost,
            limits=cfg["limits"],
        )
        return point, f"validation: group k-fold by {by}, k={k}"

    def fit(self, model: Any, dataset: Dataset, *, seed: int, out: Path) -> TaskResult:
        split = split_by_trial(
            dataset, test_size=self.test_size, val_size=0.0, seed=seed
        )
        train, _, test = split.apply(dataset)
        f_train, f_test = self.features(train), self.features(test)
        log.info(
            "frames: %d train (%d trials), %d test (%d trials)",
            len(f_train.y),
            len(train),
            len(f_test.y),
            len(test),
        )
        model, info = self.fit_model(model, f_train, seed=seed)
        chosen = self.choose_debounce(model, train, f_train)
        if chosen is not None:
            point, source = chosen
            model.debounce_k_ = point.debounce_k
            info["operating_point"] = {
                **point.record(source),
                "threshold": None,  # the classifier's own decision (predict)
            }
        else:
            info["operating_point"] = {
                "threshold": None,
                "debounce_k": self.debounce_k,
                "from": "fixed (task.debounce_k)",
            }
        m_train, _ = self.score(model, train, f_train)
        m_test, table = self.score(model, test, f_test)
        table.to_csv(out / "test_predictions.csv", index=False)
        truths, rows = self.truths(test, f_test)
        pred = table["pred"].to_numpy()
        _, events = evaluate_point(
            truths,
            [(pred[r] == SLIP).astype(np.float64) for r in rows],
            0.5,
            self.debounce_of(model),
            self.cost,
        )
        events_table(events, self.cost).to_csv(out / "test_events.csv", index=False)
        metrics = {
            "variant": self.variant,
            "n_slip": self.n_slip,
            "n_features": int(f_train.X.shape[1]),
            "split": {"train": list(split.train), "test": list(split.test)},
            **info,
            "train": m_train,
            "test": m_test,
            "majority_baseline_test": float(np.mean(f_test.y == STATIC)),
        }
        return TaskResult(model, metrics, _summary(metrics))

    def evaluate(self, model: Any, dataset: Dataset, *, out: Path) -> dict[str, Any]:
        feats = self.features(dataset)
        metrics, table = self.score(model, dataset, feats)
        table.to_csv(out / "predictions.csv", index=False)
        return {
            "test": metrics,
            "majority_baseline_test": float(np.mean(feats.y == STATIC)),
        }


def _check_pin_count(model: Any, feats: DatasetFeatures, variant: str) -> None:
    """Refuse per-pin features of another pin count (pooled models take any count)."""
    if getattr(model, "pin_count_independent", False):
        return
    want = getattr(model, "n_features_in_", None)
    have = int(feats.X.shape[1])
    if want is None or int(want) == have:
        return
    per_pin = 1 if variant in ("dr", "dtheta") else 2
    raise SlipkitError(
        f"the model was trained on {int(want) // per_pin} pins ({int(want)} per-pin "
        f"{variant} features); this dataset's pins stream has {have // per_pin} pins "
        f"({have} features): the pin count and layout are part of a per-pin model; "
        "retrain on this sensor, or train a pin-count-independent model "
        "(model=tactip_svm_pooled or detector=tactip_alignment)"
    )


def _svm_params(model: Any) -> dict[str, Any]:
    # any frame classifier (e.g. configs/model/tactip_nystroem.yaml, a Pipeline) is
    # named by its class; the SVM's own parameters are added when it has them
    params = {
        "estimator": type(model).__name__,
        "kernel": getattr(model, "kernel", None),
        "C": getattr(model, "C", None),
    }
    gamma = getattr(model, "gamma_", None)
    if gamma is not None:
        params["gamma"] = float(gamma)
        params["kernel_scale"] = float(model.kernel_scale_)
    return params


def _summary(metrics: Mapping[str, Any]) -> list[str]:
    test = metrics["test"]
    det = test["detection"]
    p = metrics["params"]
    ks = (
        f", KS {p['kernel_scale']:.4g} (gamma {p['gamma']:.3g})" if "gamma" in p else ""
    )
    val = metrics["validation"]
    what = (
        f"{p['kernel']} SVM on {metrics['variant']} (N={metrics['n_slip']}): C {p['C']:.4g}{ks}"
        if p.get("kernel") is not None and p.get("C") is not None
        else f"{p.get('estimator', 'model')} on {metrics['variant']} (N={metrics['n_slip']})"
    )
    lines = [
        f"TacTip {what}",
        f"  validation ({val['cv']}, k={val['k']}, training side only): "
        f"{val['scoring']} {val[val['scoring']]:.4f}",
        f"  test frames {test['accuracy'] * 100:.2f} % correct "
        f"(majority {metrics['majority_baseline_test'] * 100:.2f} %), balanced "
        f"{test['balanced_accuracy']:.3f}",
        f"  online ({det['debounce_k']} frames): {det['detected']}/{det['n_trials']} slips "
        f"detected, median delay {det['median_frames']} frames = {det['median_ms']:.1f} ms",
    ]
    op = metrics.get("operating_point")
    if op:
        lines.append(f"  debounce {op['debounce_k']} from {op['from']}")
    if "selection" in metrics:
        lines.insert(1, "  " + format_best(metrics["selection"]))
    return lines


__all__: Sequence[str] = ["TacTipFrames"]
