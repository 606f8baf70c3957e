"""Force direction from electrodes (the Robotic-Finger recordings): the angle between the
predicted and the measured 3-axis force, per split (block, random), with the constant-direction
controls. The task shares its data helpers with :mod:`slipkit.families.biotac.force_task`.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from sklearn.base import RegressorMixin as _RegressorMixin
from sklearn.base import clone

from slipkit.data.dataset import Dataset
from slipkit.data.splits import split_by_group, split_by_trial
from slipkit.errors import SlipkitError
from slipkit.families.biotac.force_task import (
    Frames,
    Sides,
    _block_cv,
    _channels,
    _compare_models,
    _fit_info,
    _fit_with_val,
    _markdown,
    _stream,
    _target_rows,
    log,
)
from slipkit.train.task import Task, TaskResult, analytic_estimators

# -- force direction (Robotic-Finger) ----------------------------------------------------


def angle_errors_deg(pred: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """Angle (deg) between each predicted vector, normalised, and the unit truth.

    A zero prediction has no direction; it counts as 90 deg (orthogonal to any truth).
    """
    p = np.asarray(pred, dtype=np.float64)
    u = np.asarray(truth, dtype=np.float64)
    norm = np.linalg.norm(p, axis=1, keepdims=True)
    unit = np.divide(p, norm, out=np.zeros_like(p), where=norm > 0)
    u = u / np.linalg.norm(u, axis=1, keepdims=True)
    cos = np.clip(np.einsum("ij,ij->i", unit, u), -1.0, 1.0)
    return np.asarray(np.degrees(np.arccos(cos)))


def _angle_stats(errors: np.ndarray) -> dict[str, Any]:
    return {
        "n": len(errors),
        "angle_mean_deg": float(np.mean(errors)) if len(errors) else float("nan"),
        "angle_median_deg": float(np.median(errors)) if len(errors) else float("nan"),
        "angle_p90_deg": float(np.percentile(errors, 90))
        if len(errors)
        else float("nan"),
    }


def contiguous_block_split(
    order: np.ndarray, *, test_size: float, val_size: float, seed: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Positions (into ``order``) of a contiguous test block, a contiguous val block and
    the rest (train).

    ``order`` lists the samples in recording (file) order. The test block holds
    ``ceil(test_size * n)`` consecutive samples starting at one of ``round(1 /
    test_size)`` aligned offsets, picked by ``seed``; the val block is the
    ``ceil(val_size * n_rest)`` samples just before it in the remaining order (wrapping
    to the end when the test block starts the recording).
    """
    n = len(order)
    if not 0.0 < test_size < 1.0 or not 0.0 <= val_size < 1.0:
        raise ValueError(
            f"test_size must be in (0, 1) and val_size in [0, 1); got {test_size}, "
            f"{val_size}"
        )
    n_test = int(np.ceil(test_size * n))
    n_pos = max(1, round(1.0 / test_size))
    start = min((seed % n_pos) * n // n_pos, n - n_test)
    test = np.arange(start, start + n_test)
    rest = np.concatenate([np.arange(start), np.arange(start + n_test, n)])
    n_val = int(np.ceil(val_size * len(rest)))
    if len(rest) - n_val < 1:
        raise ValueError(f"cannot split {n} samples: no training sample left")
    # The val block ends where the test block starts (rest is in recording order).
    val_end = start if start >= n_val else len(rest)
    val = rest[val_end - n_val : val_end] if n_val else rest[:0]
    train = np.setdiff1d(rest, val)
    return train, val, test


#: Split kinds of :class:`FingerDirection`.
SPLITS = ("block", "random")


class FingerDirection(Task):
    """Electrode snapshots -> unit force direction, scored by angle error (deg).

    For the Robotic-Finger recordings (``configs/source/robotic_finger.yaml``): 19
    mean-centred electrode values per sample, the unit direction ``(ux, uy, uz)`` of
    the contact force and no magnitude. The model regresses the three components;
    its output is normalised before scoring.

    Splits. That dataset offers no grouping: its author's filtering lost the time
    order, so every sample is its own trial. ``random`` splits samples at random;
    neighbouring samples of one contact then land on both sides, which flatters the
    test figures. ``block`` holds out one contiguous block of the samples in file
    order (:func:`contiguous_block_split`): if the file order still follows the
    recording in stretches (contact sessions), whole stretches stay on one side and
    only the block's two edges touch the training side; if the filtering shuffled the
    samples, ``block`` is no better than ``random``. Nothing in the data says which,
    so ``block`` is a harder split, not a guarantee of unseen sessions. Give ``group``
    when a dataset has a grouping column (object, session) to split by it instead.

    The run's objective is ``validation.angle_mean_deg``: the main model refitted on
    ``cv`` contiguous chunks of the training side (GroupKFold, each chunk held out
    once), never the test side.

    Parameters
    ----------
    stream : str
        Input stream (electrodes).
    target : str
        Direction stream (unit vectors; normalised again here).
    axes : sequence of str
        Its channels.
    group : str or None
        A trials-table column to split by (``split_by_group``); None: ``split``.
    split : {"block", "random"}
        The primary split (saved model, ``test``, objective) when ``group`` is None.
    also_split : sequence of str
        Further splits whose scores are reported beside (``splits.<kind>``).
    order : str or None
        Trials column giving the recording order for ``block`` (Robotic-Finger:
        ``sample``); None: the trials table's order.
    test_size, val_size : float
        Held-out fractions (val: of the training side, for the networks' early
        stopping; other models fit on train and val together).
    cv : int
        Contiguous chunks of the training side for the validation score (0: none).
    model_name : str
        Row name of the main model in the comparison.
    compare : mapping or list, optional
        Further models fitted on the same split (``comparison.csv/.md``).
    """

    accepts = (_RegressorMixin,)
    refuses = analytic_estimators()
    feeds = "fits a learned regressor on frames of stream {stream}"

    objective = "validation.angle_mean_deg"
    direction = "minimize"

    def __init__(
        self,
        *,
        stream: str = "electrodes",
        target: str = "truth_force_dir",
        axes: Sequence[str] = ("ux", "uy", "uz"),
        group: str | None = None,
        split: str = "random",
        also_split: Sequence[str] = (),
        order: str | None = "sample",
        test_size: float = 0.2,
        val_size: float = 0.2,
        cv: int = 3,
        model_name: str = "model",
        compare: Any = None,
    ) -> None:
        self.stream = stream
        self.target = target
        self.axes = axes
        self.group = group
        self.split = split
        self.also_split = also_split
        self.order = order
        self.test_size = test_size
        self.val_size = val_size
        self.cv = cv
        self.model_name = model_name
        self.compare = compare

    def frames(self, dataset: Dataset) -> Frames:
        """(X, y) of every sample; ``y`` normalised to unit length."""
        table = _stream(dataset, self.stream)
        channels = _channels(dataset, self.stream, None)
        merged, axes = _target_rows(dataset, table, self.target, self.axes)
        row = merged["_row"].to_numpy()
        y = merged[axes].to_numpy(dtype=np.float64)
        norm = np.linalg.norm(y, axis=1)
        if np.any(norm == 0):
            bad = merged["trial_id"].to_numpy()[norm == 0][0]
            raise SlipkitError(
                f"stream {self.target!r}: trial {bad!r} has a zero direction vector"
            )
        return Frames(
            X=table[channels].to_numpy(dtype=np.float64)[row],
            y=y / norm[:, None],
            t=merged["t"].to_numpy(dtype=np.float64),
            trial=merged["trial_id"].astype(str).to_numpy(),
            row=row,
        )

    # -- splits -------------------------------------------------------------------------
    def _recording_order(self, dataset: Dataset) -> np.ndarray:
        trials = dataset.trials
        if self.order is None:
            return trials["trial_id"].astype(str).to_numpy()
        if self.order not in trials.columns:
            raise SlipkitError(
                f"task.order={self.order!r}: no such trials column; columns: "
                f"{sorted(trials.columns)}"
            )
        ranked = trials.sort_values(self.order, kind="stable")
        return ranked["trial_id"].astype(str).to_numpy()

    def sides(self, dataset: Dataset, frames: Frames, kind: str, *, seed: int) -> Sides:
        """Train / val / test masks over ``frames`` for split ``kind`` (or ``group``)."""
        test_size, val_size = float(self.test_size), float(self.val_size)
        try:
            if self.group is not None and kind == self.split:
                split = split_by_group(
                    dataset,
                    self.group,
                    test_size=test_size,
                    val_size=val_size,
                    seed=seed,
                )
            elif kind == "random":
                split = split_by_trial(
                    dataset, test_size=test_size, val_size=val_size, seed=seed
                )
            elif kind == "block":
                order = self._recording_order(dataset)
                tr, va, te = contiguous_block_split(
                    order, test_size=test_size, val_size=val_size, seed=seed
                )
                return Sides(
                    train=np.isin(frames.trial, order[tr]),
                    val=np.isin(frames.trial, order[va]),
                    test=np.isin(frames.trial, order[te]),
                )
            else:
                raise SlipkitError(
                    f"task.split / task.also_split: {kind!r}; expected one of "
                    f"{list(SPLITS)}"
                )
        except (ValueError, KeyError) as exc:
            raise SlipkitError(f"cannot split {dataset.name!r}: {exc}") from None
        return Sides(
            train=np.isin(frames.trial, split.train),
            val=np.isin(frames.trial, split.val),
            test=np.isin(frames.trial, split.test),
        )

    def _split_name(self, kind: str) -> str:
        if self.group is not None and kind == self.split:
            return self.group
        return {"random": "trial (sample), random", "block": "contiguous block"}[kind]

    def validation(
        self, model: Any, dataset: Dataset, frames: Frames, sides: Sides
    ) -> dict[str, Any]:
        """Angle errors of ``model`` (clones) over ``cv`` contiguous chunks of the
        training side (train + val) in recording order, each held out once."""
        order = self._recording_order(dataset)
        pos = {tid: i for i, tid in enumerate(order)}
        fit_side = np.flatnonzero(sides.train | sides.val)
        fit_side = fit_side[np.argsort([pos[t] for t in frames.trial[fit_side]])]
        k = int(self.cv)
        chunks = np.zeros(len(frames.y), dtype=np.int64)
        chunks[fit_side] = np.arange(len(fit_side)) * k // len(fit_side)
        return {
            "cv": "group-kfold by contiguous chunk (file order)",
            **_block_cv(
                model,
                frames,
                fit_side,
                chunks,
                k,
                lambda p, mask: np.mean(angle_errors_deg(p[mask], frames.y[mask])),
                "angle_mean_deg",
                "finger direction validation",
            ),
        }

    def _score_split(
        self, frames: Frames, sides: Sides, models: Mapping[str, Any]
    ) -> tuple[dict[str, Any], dict[str, Any]]:
        """Fit every model on ``sides``; (per-model scores, constant baseline)."""
        fit_side = sides.train | sides.val
        mean_dir = frames.y[fit_side].mean(axis=0)
        mean_dir = mean_dir / np.linalg.norm(mean_dir)
        comparison: dict[str, Any] = {}
        for name, est in models.items():
            log.info("fitting %s (%s)", name, type(est).__name__)
            fitted_on = _fit_with_val(est, frames.X, frames.y, sides)
            err = angle_errors_deg(np.asarray(est.predict(frames.X)), frames.y)
            comparison[name] = {
                "fit": {**_fit_info(est), "fitted_on": fitted_on},
                **{
                    side: _angle_stats(err[mask])
                    for side, mask in (
                        ("train", sides.train),
                        ("val", sides.val),
                        ("test", sides.test),
                    )
                },
            }
        base_err = angle_errors_deg(np.broadcast_to(mean_dir, frames.y.shape), frames.y)
        baseline = {
            "direction": mean_dir.tolist(),
            "train": _angle_stats(base_err[sides.train]),
            "test": _angle_stats(base_err[sides.test]),
        }
        return comparison, baseline

    def fit(self, model: Any, dataset: Dataset, *, seed: int, out: Path) -> TaskResult:
        frames = self.frames(dataset)
        kinds = list(dict.fromkeys([str(self.split), *map(str, self.also_split)]))
        splits: dict[str, Any] = {}
        main_name = str(self.model_name)
        for kind in kinds:
            sides = self.sides(dataset, frames, kind, seed=seed)
            primary = kind == kinds[0]
            # Every split fits fresh models; the primary split's main model is saved.
            est = model if primary else clone(model)
            models = {main_name: est, **_compare_models(self.compare)}
            comparison, baseline = self._score_split(frames, sides, models)
            entry: dict[str, Any] = {
                "by": self._split_name(kind),
                "train": int(sides.train.sum()),
                "val": int(sides.val.sum()),
                "test": int(sides.test.sum()),
                "comparison": comparison,
                "constant_mean_direction": baseline,
            }
            if primary:
                entry["validation"] = (
                    self.validation(model, dataset, frames, sides)
                    if int(self.cv) > 1
                    else None
                )
            splits[kind] = entry
        first = splits[kinds[0]]
        rows = {n: _angle_row(c) for n, c in first["comparison"].items()}
        rows["constant mean direction"] = _angle_row(first["constant_mean_direction"])
        table = pd.DataFrame.from_dict(rows, orient="index")
        table.index.name = "model"
        for kind in kinds[1:]:
            other = splits[kind]
            for n, c in other["comparison"].items():
                table.loc[n, f"mean_test_{kind}"] = c["test"]["angle_mean_deg"]
            table.loc["constant mean direction", f"mean_test_{kind}"] = other[
                "constant_mean_direction"
            ]["test"]["angle_mean_deg"]
        table.to_csv(out / "comparison.csv")
        (out / "comparison.md").write_text(
            "# Force direction: angle error (deg) of the normalised prediction\n\n"
            f"Columns without a suffix: the {kinds[0]} split"
            + "".join(f"; `_{k}`: the test side of the {k} split" for k in kinds[1:])
            + ".\n\n"
            + _markdown(table, ".1f"),
            encoding="utf-8",
        )
        main = first["comparison"][main_name]
        metrics: dict[str, Any] = {
            "model": main_name,
            "split": {
                "by": first["by"],
                "train": first["train"],
                "val": first["val"],
                "test": first["test"],
            },
            "fit": main["fit"],
            "validation": first.get("validation"),
            "train": main["train"],
            "val": main["val"],
            "test": main["test"],
            "constant_mean_direction": first["constant_mean_direction"],
            "comparison": first["comparison"],
            "splits": {
                k: {
                    key: v
                    for key, v in entry.items()
                    if key not in ("comparison", "validation")
                }
                | {"test": {n: c["test"] for n, c in entry["comparison"].items()}}
                for k, entry in splits.items()
            },
        }
        lines = [
            f"Force direction on {dataset.name or dataset.sensor} "
            f"(split by {first['by']}: {first['train']} train / {first['val']} val / "
            f"{first['test']} test samples)",
        ]
        val = metrics["validation"]
        if val:
            lines.append(
                f"  validation ({val['cv']}, k={val['k']}, training side only): "
                f"{main_name} mean angle {val['angle_mean_deg']:.2f} deg"
            )
        lines.append(
            f"  {'model':<24} {'train mean / median (deg)':>26} "
            f"{'test mean / median (deg)':>26}"
            + "".join(f" {'test mean, ' + k:>18}" for k in kinds[1:])
        )
        for name, r in rows.items():
            extra = "".join(
                f" {table.loc[name, f'mean_test_{k}']:>18.1f}" for k in kinds[1:]
            )
            lines.append(
                f"  {name:<24} {r['mean_train']:>12.1f} / {r['median_train']:<11.1f} "
                f"{r['mean_test']:>12.1f} / {r['median_test']:<11.1f}{extra}"
            )
        return TaskResult(model, metrics, lines)

    def evaluate(self, model: Any, dataset: Dataset, *, out: Path) -> dict[str, Any]:
        """Angle errors over every sample of ``dataset`` as ``test``, per-sample errors in
        ``angle_errors.csv``."""
        frames = self.frames(dataset)
        err = angle_errors_deg(np.asarray(model.predict(frames.X)), frames.y)
        mean_dir = frames.y.mean(axis=0)
        mean_dir = mean_dir / np.linalg.norm(mean_dir)
        base = angle_errors_deg(np.broadcast_to(mean_dir, frames.y.shape), frames.y)
        pd.DataFrame({"trial_id": frames.trial, "angle_error_deg": err}).to_csv(
            out / "angle_errors.csv", index=False
        )
        return {
            "model": str(self.model_name),
            "test": _angle_stats(err),
            # This dataset's own mean direction: an oracle constant, the best any
            # constant can do here (the training mean is not stored with the model).
            "constant_mean_direction_oracle": _angle_stats(base),
        }


def _angle_row(scores: Mapping[str, Mapping[str, Any]]) -> dict[str, float]:
    return {
        f"{stat}_{side}": float(scores[side][f"angle_{stat}_deg"])
        for side in ("train", "test")
        for stat in ("mean", "median")
    }


__all__ = ["FingerDirection", "angle_errors_deg", "contiguous_block_split"]
