"""SlipTack speed and acceleration estimation (SlipTack paper, seed 000).

:class:`SlipTackSpeed` (``sliptack_pull``): per material, the speed estimator is
calibrated on the training trials (with the material's friction when ``friction`` names
it), every test trial's speed is the median of the per-sample estimates over its steady
pull, and the dominant frequency of the whole steady pull (the paper's Fig. 8) is plotted
against speed beside the model curve: cherry and basswood follow it, acrylic does not.

:class:`SlipTackAccel` (``sliptack_drop``): eq. 4 on the gross deflection (G) and eq. 5 on
the frequency slope (SF), each calibrated by linear regression on the training trials'
samples inside the paper's window (0.06 s after the release up to 150 mm of travel) and
scored by the trial-mean acceleration against the label.
"""

from __future__ import annotations

import logging
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from sklearn.base import clone

from slipkit.data.dataset import Dataset, Trial
from slipkit.data.splits import TrialSplit, split_by_trial
from slipkit.errors import SlipkitError
from slipkit.families.sliptack.accel import DropAcceleration as _DropAcceleration
from slipkit.families.sliptack.spectral import (
    SpectralSpeedRegressor as _SpectralSpeedRegressor,
)
from slipkit.families.sliptack.speed import StickSlipSpeed as _StickSlipSpeed
from slipkit.train.search import trial_cv
from slipkit.train.task import Task, TaskResult, register_analytic_estimator

log = logging.getLogger("slipkit.sliptack")
#: any material the training side did not hold
DEFAULT = "*"


def _split(dataset: Dataset, test_size: float, seed: int, group: str) -> TrialSplit:
    """Trial split stratified by ``group`` when every group has >= 2 trials."""
    try:
        return split_by_trial(dataset, test_size=test_size, seed=seed, stratify=group)
    except (ValueError, KeyError):
        return split_by_trial(dataset, test_size=test_size, seed=seed)


def _validation(train: Dataset, fit_score: Any, cv: int, label: str) -> dict[str, Any]:
    """Group CV by trial on the training half (the run's objective), never the test
    half; a SplitError (one line) when the training half has fewer than 2 trials."""
    return trial_cv(train.trial_ids, fit_score, cv=int(cv), label=label)


def _column(trial: Trial, stream: str, column: str) -> np.ndarray:
    table = trial.streams.get(stream)
    if table is None:
        raise SlipkitError(
            f"trial {trial.trial_id}: no stream {stream!r} (has {sorted(trial.streams)})"
        )
    if column not in table.columns:
        raise SlipkitError(
            f"trial {trial.trial_id}: stream {stream!r} has no column {column!r} "
            f"(has {[c for c in table.columns if c != 't']})"
        )
    return table[column].to_numpy(dtype=np.float64)


def _label(trial: Trial, name: str) -> float:
    if name not in trial.labels:
        raise SlipkitError(
            f"trial {trial.trial_id}: no label {name!r} (has {sorted(trial.labels)})"
        )
    return float(trial.labels[name])


def _stats(err: np.ndarray) -> dict[str, float]:
    e = err[np.isfinite(err)]
    nan = float("nan")
    return {
        "mae": float(np.mean(np.abs(e))) if len(e) else nan,
        "rmse": float(np.sqrt(np.mean(e * e))) if len(e) else nan,
        "bias": float(np.mean(e)) if len(e) else nan,
    }


def _corr(a: np.ndarray, b: np.ndarray) -> float:
    ok = np.isfinite(a) & np.isfinite(b)
    if ok.sum() < 3 or np.ptp(a[ok]) == 0 or np.ptp(b[ok]) == 0:
        return float("nan")
    return float(np.corrcoef(a[ok], b[ok])[0, 1])


# -- speed ------------------------------------------------------------------------------------
class SlipTackSpeed(Task):
    """Speed from the stick-slip frequency, per material, on ``sliptack_pull``.

    Parameters
    ----------
    friction : mapping or None
        Per material ``{mu_s, mu_k}`` set on the estimator before it is fitted (the paper
        measured them, Fig. 4(b)); None: the estimator's own values for every material.
    group : str
        Group column naming the material.
    test_size : float
        Fraction of trials held out.
    follows_model_pct : float
        A material "follows the model" when the median |f_d - f_model| / f_model of its
        test trials is below this (%).
    stream, column : str
        Nib stream and its channel.
    truth_stream, truth_column : str
        Ground-truth speed (mm/s) per sample.
    speed_label, onset_label : str
        Trial labels: pull speed (mm/s) and pull start (s).
    """

    accepts = (_StickSlipSpeed, _SpectralSpeedRegressor)
    refuses = ()
    feeds = (
        "runs the SlipTack speed estimator (eq. 3 inverted) or a learned spectral one"
    )

    #: validation: calibrations refitted by group CV by trial on the training half
    objective = "validation.overall.mae_mm_s"
    direction = "minimize"

    def __init__(
        self,
        *,
        friction: Mapping[str, Mapping[str, float]] | None = None,
        group: str = "material",
        test_size: float = 0.5,
        follows_model_pct: float = 15.0,
        stream: str = "nib",
        column: str = "deflection",
        truth_stream: str = "truth_motion",
        truth_column: str = "speed",
        speed_label: str = "speed_mm_s",
        onset_label: str = "slip_onset_s",
        cv: int = 3,
    ) -> None:
        self.cv = cv
        self.friction = friction
        self.group = group
        self.test_size = test_size
        self.follows_model_pct = follows_model_pct
        self.stream = stream
        self.column = column
        self.truth_stream = truth_stream
        self.truth_column = truth_column
        self.speed_label = speed_label
        self.onset_label = onset_label

    # -- data ---------------------------------------------------------------------------
    def _material(self, trial: Trial) -> str:
        if self.group not in trial.meta:
            raise SlipkitError(
                f"trial {trial.trial_id}: no group {self.group!r} (has {sorted(trial.meta)})"
            )
        return str(trial.meta[self.group])

    def _steady(self, trial: Trial, model: Any) -> np.ndarray:
        """Samples whose whole analysis window lies inside the pull."""
        t = trial.streams[self.stream]["t"].to_numpy()
        lag = (int(model.window) - 1) / float(model.rate_hz)
        return np.asarray(t - lag >= _label(trial, self.onset_label))

    def _inputs(self, trial: Trial, x: np.ndarray, model: Any) -> np.ndarray:
        """The estimator's X for one trial: the nib column, plus the trial's normal force
        (label ``normal_force_N``, N) when the estimator reads it (``normal_force="input"``)."""
        if getattr(model, "normal_force", "value") != "input":
            return x[:, None]
        return np.c_[x, np.full(len(x), _label(trial, "normal_force_N"))]

    def _check_rate(self, dataset: Dataset, model: Any) -> None:
        """The estimator's rate_hz must be the stream's (its Nyquist check relies on it)."""
        spec = dataset.streams.get(self.stream)
        rate = getattr(spec, "rate_hz", None)
        if (
            rate is not None
            and hasattr(model, "rate_hz")
            and abs(float(rate) - float(model.rate_hz)) > 1e-6 * float(rate)
        ):
            raise SlipkitError(
                f"stream {self.stream!r} is sampled at {float(rate):g} Hz but the "
                f"estimator's rate_hz is {float(model.rate_hz):g} Hz; set "
                f"detector.rate_hz={float(rate):g} (and a window that fits a trial)"
            )

    def _xy(self, dataset: Dataset, model: Any) -> tuple[np.ndarray, ...]:
        self._check_rate(dataset, model)
        xs, ys, segs = [], [], []
        for i, trial in enumerate(dataset):
            x = _column(trial, self.stream, self.column)
            v = _column(trial, self.truth_stream, self.truth_column)
            if len(v) != len(x):
                raise SlipkitError(
                    f"trial {trial.trial_id}: {self.truth_stream!r} and {self.stream!r} "
                    "differ in length; the speed task needs them sample-aligned"
                )
            xs.append(self._inputs(trial, x, model))
            ys.append(np.where(self._steady(trial, model), v, np.nan))
            segs.append(np.full(len(x), i))
        return np.concatenate(xs), np.concatenate(ys), np.concatenate(segs)

    def _estimator(self, model: Any, material: str) -> Any:
        est = clone(model)
        if self.friction and material in self.friction:
            est.set_params(**{k: float(v) for k, v in self.friction[material].items()})
        return est

    # -- fit / score ------------------------------------------------------------------
    def fit_models(self, model: Any, train: Dataset) -> dict[str, Any]:
        """One calibrated estimator per training material, plus ``"*"`` for unseen ones."""
        models: dict[str, Any] = {}
        by_material: dict[str, list[str]] = {}
        for trial in train:
            by_material.setdefault(self._material(trial), []).append(trial.trial_id)
        for material, ids in sorted(by_material.items()):
            X, y, seg = self._xy(train.subset(ids), model)
            models[material] = self._estimator(model, material).fit(X, y, segments=seg)
        X, y, seg = self._xy(train, model)
        models[DEFAULT] = clone(model).fit(X, y, segments=seg)
        return models

    def trial_table(self, models: Mapping[str, Any], dataset: Dataset) -> pd.DataFrame:
        """One row per trial: true and estimated speed, dominant and model frequency."""
        self._check_rate(dataset, models[DEFAULT])
        rows = []
        for trial in dataset:
            material = self._material(trial)
            est = models.get(material, models[DEFAULT])
            x = _column(trial, self.stream, self.column)
            steady = self._steady(trial, est)
            pred = est.predict(self._inputs(trial, x, est))[steady]
            t = trial.streams[self.stream]["t"].to_numpy()
            pull = x[t >= _label(trial, self.onset_label)]
            f_d = est.segment_frequency(pull)  # the paper: one spectrum per pull
            v = _label(trial, self.speed_label)
            fn = (
                _label(trial, "normal_force_N")
                if getattr(est, "normal_force", "value") == "input"
                else None
            )  # the model curve at the trial's measured force, when the estimator reads it
            f_model = float(est.frequency_from_speed(v, fn))
            finite = pred[np.isfinite(pred)]
            v_hat = float(np.median(finite)) if len(finite) else float("nan")
            rows.append(
                {
                    "trial_id": trial.trial_id,
                    "material": material,
                    "speed_mm_s": v,
                    "speed_est_mm_s": v_hat,
                    "speed_err_mm_s": v_hat - v,
                    "undefined_fraction": float(1 - len(finite) / max(len(pred), 1)),
                    "f_d_hz": f_d,
                    "f_model_hz": f_model,
                    "f_dev_pct": 100.0 * (f_d - f_model) / f_model,
                }
            )
        return pd.DataFrame(rows)

    def summarise(self, table: pd.DataFrame) -> dict[str, Any]:
        """Per-material and overall speed errors and frequency deviations."""
        out: dict[str, Any] = {}
        for material, part in [*table.groupby("material"), ("overall", table)]:
            err = part["speed_err_mm_s"].to_numpy()
            s = _stats(err)
            dev = np.abs(part["f_dev_pct"].to_numpy())
            med_dev = float(np.nanmedian(dev)) if np.isfinite(dev).any() else np.nan
            out[str(material)] = {
                "n_trials": len(part),
                "mae_mm_s": s["mae"],
                "rmse_mm_s": s["rmse"],
                "bias_mm_s": s["bias"],
                "mean_rel_err_pct": float(
                    np.nanmean(100 * np.abs(err) / part["speed_mm_s"].to_numpy())
                )
                if np.isfinite(err).any()
                else float("nan"),
                "undefined_trials": int((~np.isfinite(err)).sum()),
                "median_abs_f_dev_pct": med_dev,
                "r_f_speed": _corr(
                    part["f_d_hz"].to_numpy(), part["speed_mm_s"].to_numpy()
                ),
                # Only a material can follow the model; the pooled row mixes them.
                "follows_model": bool(med_dev < self.follows_model_pct)
                if material != "overall"
                else None,
            }
        return out

    def _write(self, models: Mapping[str, Any], table: pd.DataFrame, out: Path) -> None:
        table.to_csv(out / "speed_trials.csv", index=False)
        grid = np.linspace(5.0, 105.0, 101)
        curves = pd.DataFrame({"speed_mm_s": grid})
        for material, est in models.items():
            if material != DEFAULT:
                curves[f"f_model_{material}_hz"] = est.frequency_from_speed(grid)
        curves.to_csv(out / "model_curve.csv", index=False)
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        fig, ax = plt.subplots(figsize=(6.4, 4.2))
        for i, (key, part) in enumerate(table.groupby("material")):
            name, color = str(key), f"C{i}"
            ax.plot(
                part["speed_mm_s"],
                part["f_d_hz"],
                "x",
                color=color,
                label=f"{name} (simulated)",
            )
            col = f"f_model_{name}_hz"
            if col in curves:
                ax.plot(grid, curves[col], "--", color=color, label=f"{name} model")
        ax.set_xlabel("pull speed (mm/s)")
        ax.set_ylabel("dominant frequency f_d (Hz)")
        ax.set_title("SlipTack Fig. 8: dominant frequency vs speed")
        ax.legend(fontsize=7)
        fig.tight_layout()
        fig.savefig(out / "frequency_vs_speed.png", dpi=100)
        plt.close(fig)

    def fit(self, model: Any, dataset: Dataset, *, seed: int, out: Path) -> TaskResult:
        split = _split(dataset, self.test_size, seed, self.group)
        train, _, test = split.apply(dataset)
        log.info("trials: %d train, %d test", len(train), len(test))
        models = self.fit_models(model, train)  # its own errors come first
        validation = _validation(
            train,
            lambda a, b: self.summarise(
                self.trial_table(
                    self.fit_models(model, train.subset(a)), train.subset(b)
                )
            ),
            self.cv,
            "SlipTack speed validation",
        )
        m_train = self.summarise(self.trial_table(models, train))
        table = self.trial_table(models, test)
        m_test = self.summarise(table)
        self._write(models, table, out)
        first = models[DEFAULT]
        metrics = {
            "form": first.form,
            "split": {"train": list(split.train), "test": list(split.test)},
            "stick_length_mm": {
                k: 1e3 * float(m.stick_length_m_) for k, m in models.items()
            },
            "saturation_hz": float(first.saturation_hz_),
            "validation": validation,
            "train": m_train,
            "test": m_test,
        }
        return TaskResult(models, metrics, _speed_summary(metrics))

    def evaluate(self, model: Any, dataset: Dataset, *, out: Path) -> dict[str, Any]:
        table = self.trial_table(model, dataset)
        table.to_csv(out / "speed_trials.csv", index=False)
        return {"test": self.summarise(table)}


def _speed_summary(metrics: Mapping[str, Any]) -> list[str]:
    test = metrics["test"]
    lines = [
        f"SlipTack speed from stick-slip frequency (eq. 3 {metrics['form']} form inverted, "
        f"saturation {metrics['saturation_hz']:.1f} Hz), test trials:",
        f"  {'material':<10}{'n':>3}{'MAE mm/s':>10}{'rel %':>8}{'|f-model| %':>13}"
        f"{'r(f,v)':>8}  follows model",
    ]
    for name, m in test.items():
        lines.append(
            f"  {name:<10}{m['n_trials']:>3}{m['mae_mm_s']:>10.1f}"
            f"{m['mean_rel_err_pct']:>8.1f}{m['median_abs_f_dev_pct']:>13.1f}"
            f"{m['r_f_speed']:>8.2f}  "
            f"{ {True: 'yes', False: 'no', None: '-'}[m['follows_model']] }"
        )
    lines.append(
        "  paper (Fig. 8): cherry and basswood follow the model, acrylic shows no "
        "consistent trend (adhesion)"
    )
    return lines


# -- acceleration -------------------------------------------------------------------------------
class SlipTackAccel(Task):
    """Drop acceleration from the gross deflection (eq. 4) and the frequency slope (eq. 5).

    Parameters
    ----------
    features : list of str
        Features of :class:`~slipkit.families.sliptack.accel.DropAcceleration` to compare
        (each a clone of the configured estimator with ``feature`` set).
    test_size : float
        Fraction of trials held out.
    window_delay_s, travel_mm : float
        The paper's window: from this long after the release up to this travel.
    stream, column : str
        Nib stream and its channel.
    truth_stream : str
        Ground truth with ``acceleration`` (m/s^2) and ``position`` (mm).
    label, release_label, onset_label : str
        Trial labels: mean acceleration over the window, release and breakaway times.
    group : str
        Group column used to stratify the split.
    """

    accepts = (_DropAcceleration,)
    refuses = ()
    feeds = "runs the SlipTack drop estimator"

    #: validation: calibrations refitted by group CV by trial on the training half
    objective = "validation.deflection.rmse_m_s2"
    direction = "minimize"

    def __init__(
        self,
        *,
        features: Sequence[str] = ("deflection", "frequency_slope"),
        test_size: float = 0.5,
        window_delay_s: float = 0.06,
        travel_mm: float = 150.0,
        stream: str = "nib",
        column: str = "deflection",
        truth_stream: str = "truth_motion",
        label: str = "mean_acceleration_m_s2",
        release_label: str = "release_s",
        onset_label: str = "slip_onset_s",
        group: str = "material",
        cv: int = 3,
    ) -> None:
        self.cv = cv
        self.features = features
        self.test_size = test_size
        self.window_delay_s = window_delay_s
        self.travel_mm = travel_mm
        self.stream = stream
        self.column = column
        self.truth_stream = truth_stream
        self.label = label
        self.release_label = release_label
        self.onset_label = onset_label
        self.group = group

    def _window(self, trial: Trial) -> np.ndarray:
        t = trial.streams[self.truth_stream]["t"].to_numpy()
        pos = _column(trial, self.truth_stream, "position")
        onset = _label(trial, self.onset_label)
        start = _label(trial, self.release_label) + self.window_delay_s
        return np.asarray((t >= onset) & (t >= start) & (pos <= self.travel_mm))

    def _xy(self, dataset: Dataset) -> tuple[np.ndarray, ...]:
        xs, ys, segs = [], [], []
        for i, trial in enumerate(dataset):
            x = _column(trial, self.stream, self.column)
            a = _column(trial, self.truth_stream, "acceleration")
            if len(a) != len(x):
                raise SlipkitError(
                    f"trial {trial.trial_id}: {self.truth_stream!r} and {self.stream!r} "
                    "differ in length"
                )
            xs.append(x)
            ys.append(np.where(self._window(trial), a, np.nan))
            segs.append(np.full(len(x), i))
        return np.concatenate(xs)[:, None], np.concatenate(ys), np.concatenate(segs)

    def trial_table(self, models: Mapping[str, Any], dataset: Dataset) -> pd.DataFrame:
        """One row per trial and feature: label, trial-mean estimate and feature."""
        rows = []
        for trial in dataset:
            x = _column(trial, self.stream, self.column)[:, None]
            win = self._window(trial)
            for name, est in models.items():
                feat = est.transform_feature(x)[win]
                pred = est.predict(x)[win]
                ok = np.isfinite(pred)
                a_hat = float(np.mean(pred[ok])) if ok.any() else float("nan")
                label = _label(trial, self.label)
                rows.append(
                    {
                        "trial_id": trial.trial_id,
                        "feature": name,
                        "accel_m_s2": label,
                        "accel_est_m_s2": a_hat,
                        "err_m_s2": a_hat - label,
                        "feature_mean": float(np.mean(feat[ok]))
                        if ok.any()
                        else np.nan,
                    }
                )
        return pd.DataFrame(rows)

    def summarise(self, table: pd.DataFrame) -> dict[str, Any]:
        """Per feature: trial RMSE / MAE of the mean acceleration and |r| with the label."""
        out: dict[str, Any] = {}
        for name, part in table.groupby("feature", sort=False):
            s = _stats(part["err_m_s2"].to_numpy())
            out[str(name)] = {
                "n_trials": len(part),
                "rmse_m_s2": s["rmse"],
                "mae_m_s2": s["mae"],
                "bias_m_s2": s["bias"],
                "undefined_trials": int((~np.isfinite(part["err_m_s2"])).sum()),
                "r_feature_accel": _corr(
                    part["feature_mean"].to_numpy(), part["accel_m_s2"].to_numpy()
                ),
            }
        return out

    def fit(self, model: Any, dataset: Dataset, *, seed: int, out: Path) -> TaskResult:
        split = _split(dataset, self.test_size, seed, self.group)
        train, _, test = split.apply(dataset)

        def fit(part: Dataset) -> dict[str, Any]:
            X, y, seg = self._xy(part)
            return {
                f: clone(model).set_params(feature=f).fit(X, y, segments=seg)
                for f in self.features
            }

        models = fit(train)  # its own errors come first
        validation = _validation(
            train,
            lambda a, b: self.summarise(
                self.trial_table(fit(train.subset(a)), train.subset(b))
            ),
            self.cv,
            "SlipTack acceleration validation",
        )
        table = self.trial_table(models, test)
        table.to_csv(out / "accel_trials.csv", index=False)
        metrics = {
            "split": {"train": list(split.train), "test": list(split.test)},
            "calibration": {
                f: {"intercept_m_s2": m.intercept_, "coef": m.coef_, "r_samples": m.r_}
                for f, m in models.items()
            },
            "validation": validation,
            "train": self.summarise(self.trial_table(models, train)),
            "test": self.summarise(table),
        }
        self._plot(table, out)
        return TaskResult(models, metrics, _accel_summary(metrics))

    def _plot(self, table: pd.DataFrame, out: Path) -> None:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        fig, ax = plt.subplots(figsize=(5.2, 4.2))
        for i, (name, part) in enumerate(table.groupby("feature", sort=False)):
            ax.plot(
                part["accel_m_s2"],
                part["accel_est_m_s2"],
                "o",
                color=f"C{i}",
                label=str(name),
            )
        lim = [0.0, 10.0]
        ax.plot(lim, lim, "k:", lw=1)
        ax.set_xlabel("true mean acceleration (m/s^2)")
        ax.set_ylabel("estimated (m/s^2)")
        ax.legend(fontsize=8)
        fig.tight_layout()
        fig.savefig(out / "accel_estimates.png", dpi=100)
        plt.close(fig)

    def evaluate(self, model: Any, dataset: Dataset, *, out: Path) -> dict[str, Any]:
        table = self.trial_table(model, dataset)
        table.to_csv(out / "accel_trials.csv", index=False)
        return {"test": self.summarise(table)}


def _accel_summary(metrics: Mapping[str, Any]) -> list[str]:
    lines = [
        "SlipTack drop acceleration, test trials (trial-mean over the paper's window):"
    ]
    lines.append(
        f"  {'feature':<17}{'n':>3}{'RMSE m/s^2':>12}{'MAE':>8}{'r':>7}  calibration"
    )
    for name, m in metrics["test"].items():
        c = metrics["calibration"][name]
        lines.append(
            f"  {name:<17}{m['n_trials']:>3}{m['rmse_m_s2']:>12.2f}{m['mae_m_s2']:>8.2f}"
            f"{m['r_feature_accel']:>7.2f}  a = {c['intercept_m_s2']:.2f} "
            f"{c['coef']:+.3g} x feature"
        )
    lines.append(
        "  paper (Figs. 10-11): gross deflection (G) correlates best with acceleration; "
        "frequency slope (SF) does not"
    )
    return lines


# learned-model tasks refuse the SlipTack estimators (they read the nib stream in these tasks)
register_analytic_estimator(_StickSlipSpeed)
register_analytic_estimator(_DropAcceleration)

__all__: Sequence[str] = ["SlipTackAccel", "SlipTackSpeed"]
