"""BioTac force regression and force direction (Su et al. 2015, Humanoids, Sec. V-A).

:class:`ForceRegression`: electrode frames (optionally with the DC pressure) -> the
3-axis force (N) of a time-series dataset, split as the paper does (recordings cut
into 30 s blocks, blocks shuffled, 80 % train / 20 % test, 20 % of train for the
networks' early stopping), scored by RMSE (N) and SMSE per axis, optionally side by
side with other models on the same split.

:class:`FingerDirection`: electrode snapshots -> the unit force direction (the
Robotic-Finger recordings have no magnitude), scored by the angle (deg) between the
normalised prediction and the truth, against a constant mean direction.
"""

from __future__ import annotations

import inspect
import logging
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from sklearn.base import RegressorMixin as _RegressorMixin
from sklearn.base import clone

from slipkit.data.dataset import Dataset
from slipkit.data.splits import split_time_blocks
from slipkit.errors import SlipkitError
from slipkit.evaluate.metrics import regression_metrics
from slipkit.progress import progress_line
from slipkit.train.task import Task, TaskResult, analytic_estimators

log = logging.getLogger("slipkit.force")

#: Su et al. 2015, Sec. V-A (Fig. 6): the 3-layer network on the test set.
PAPER_TEST = {
    "rmse": {"x": 0.43, "y": 0.53, "z": 0.85},
    "smse": {"x": 0.08, "y": 0.03, "z": 0.02},
}


@dataclass(frozen=True)
class Frames:
    """Aligned model inputs and targets of a dataset.

    Attributes
    ----------
    X : ndarray of shape (n, n_features)
        Electrode values (counts; relative to the baseline when one is subtracted),
        then any extra channels.
    y : ndarray of shape (n, n_outputs)
        Targets (force in N, or a unit direction).
    t : ndarray of shape (n,)
        Time of each frame (s).
    trial : ndarray of shape (n,)
        Trial id of each frame.
    row : ndarray of shape (n,)
        Position (``iloc``) of each frame in the input stream's long table.
    """

    X: np.ndarray
    y: np.ndarray
    t: np.ndarray
    trial: np.ndarray
    row: np.ndarray


def _stream(dataset: Dataset, name: str) -> pd.DataFrame:
    if name not in dataset.tables:
        raise SlipkitError(
            f"dataset {dataset.name or dataset.sensor!r} has no stream {name!r}; "
            f"streams: {sorted(dataset.tables)}"
        )
    return dataset.stream(name).reset_index(drop=True)


def _channels(dataset: Dataset, name: str, wanted: Sequence[str] | None) -> list[str]:
    have = list(dataset.streams[name].channels)
    if wanted is None:
        return have
    missing = [c for c in wanted if c not in have]
    if missing:
        raise SlipkitError(
            f"stream {name!r} has no channel(s) {missing}; channels: {have}"
        )
    return list(wanted)


def _first_frames_median(
    table: pd.DataFrame, channels: list[str], n: int
) -> np.ndarray:
    """Per row, the median of its trial's first ``n`` frames (in time order)."""
    first = (
        table.sort_values(["trial_id", "t"], kind="stable")
        .groupby("trial_id", sort=False)
        .head(n)
        .groupby("trial_id", sort=False)[channels]
        .median()
    )
    return first.loc[table["trial_id"]].to_numpy(dtype=np.float64)


def _join(
    key: pd.DataFrame, other: pd.DataFrame, channels: list[str], what: str
) -> pd.DataFrame:
    """``key`` (trial_id, t, _row) inner-joined with ``other``'s channels on (trial_id, t)."""
    merged = key.merge(
        other[["trial_id", "t", *channels]],
        on=["trial_id", "t"],
        how="inner",
        validate="one_to_one",
    )
    if merged.empty:
        raise SlipkitError(
            f"no frame of stream {what!r} shares a (trial_id, t) with the input "
            "stream; the streams must be sampled together"
        )
    if len(merged) < len(key):
        log.warning(
            "%d of %d input frames have no %s frame at the same time; dropped",
            len(key) - len(merged),
            len(key),
            what,
        )
    return merged


def _target_rows(
    dataset: Dataset, table: pd.DataFrame, target: str, axes: Any
) -> tuple[pd.DataFrame, list[str]]:
    """The input ``table``'s rows joined with the target stream's ``axes`` on (trial_id, t).

    Returns the merged frame (``_row``: the input row of each target frame) and the axes.
    """
    key = pd.DataFrame(
        {"trial_id": table["trial_id"], "t": table["t"], "_row": np.arange(len(table))}
    )
    names = _channels(dataset, _stream_name(dataset, target), axes)
    return _join(key, _stream(dataset, target), names, target), names


def _accepts_validation(model: Any) -> bool:
    try:
        return "validation_data" in inspect.signature(model.fit).parameters
    except (TypeError, ValueError):
        return False


def _fit_with_val(model: Any, X: np.ndarray, y: np.ndarray, sides: Sides) -> str:
    """Fit ``model``: networks on train with the val side for early stopping, the
    others (which have no early stopping) on train and val together, as the paper
    holds out its validation 20 % only for the networks. Returns what was used."""
    if _accepts_validation(model) and sides.val.any():
        model.fit(
            X[sides.train], y[sides.train], validation_data=(X[sides.val], y[sides.val])
        )
        return "train (val for early stopping)"
    both = sides.train | sides.val
    model.fit(X[both], y[both])
    return "train + val"


@dataclass(frozen=True)
class Sides:
    """Boolean masks over frames."""

    train: np.ndarray
    val: np.ndarray
    test: np.ndarray


def _compare_models(compare: Any) -> dict[str, Any]:
    """Name -> fresh estimator from a mapping or a list of estimators / ``_target_`` nodes."""
    from hydra.utils import instantiate

    if compare is None:
        return {}
    if isinstance(compare, Mapping):
        items = [(str(k), v) for k, v in compare.items()]
    elif isinstance(compare, Sequence) and not isinstance(compare, str):
        items = []
        for i, node in enumerate(compare):
            target = (
                type(node).__name__
                if hasattr(node, "fit")
                else str(node.get("_target_", "model")).rsplit(".", 1)[-1]
            )
            items.append((f"{target}_{i}", node))
    else:
        raise SlipkitError(
            f"task.compare must be a mapping name -> model config or a list of model "
            f"configs; got {type(compare).__name__}"
        )
    models = {}
    for name, node in items:
        models[name] = clone(node) if hasattr(node, "fit") else instantiate(node)
    return models


def _fit_info(model: Any) -> dict[str, Any]:
    info: dict[str, Any] = {"estimator": type(model).__name__}
    for key in ("n_epochs_", "best_epoch_", "best_valid_loss_", "n_fields_", "width_"):
        if hasattr(model, key):
            info[key.rstrip("_")] = getattr(model, key)
    for key in ("scales_", "offsets_"):
        if hasattr(model, key):
            info[key.rstrip("_")] = np.asarray(getattr(model, key)).tolist()
    return info


def _markdown(table: pd.DataFrame, floatfmt: str = ".3f") -> str:
    """A GitHub markdown table (hand-written: pandas' to_markdown needs tabulate,
    which is not a slipkit dependency)."""
    cols = [str(table.index.name or ""), *map(str, table.columns)]
    lines = ["| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
    for idx, row in table.iterrows():
        cells = [
            ""
            if pd.isna(v)
            else format(v, floatfmt)
            if isinstance(v, float)
            else str(v)
            for v in row
        ]
        lines.append("| " + " | ".join([str(idx), *cells]) + " |")
    return "\n".join(lines) + "\n"


def _axis(name: str) -> str:
    """``fx`` -> ``x`` (the column label of the comparison tables)."""
    return name[1:] if len(name) == 2 and name[0] == "f" else name


def _with_means(m: dict[str, Any]) -> dict[str, Any]:
    m["rmse_mean"] = float(np.mean(list(m["rmse"].values())))
    smse = [v for v in m["smse"].values() if np.isfinite(v)]
    m["smse_mean"] = float(np.mean(smse)) if smse else float("nan")
    return m


class ForceRegression(Task):
    """Electrode frames -> 3-axis force (N), split by 30 s blocks (Su et al. 2015, Sec. V-A).

    Parameters
    ----------
    stream : str
        Input stream (electrode impedances, counts).
    pdc_stream : str or None
        A DC-pressure stream appended as an extra input column (the paper does not
        use it); None: electrodes only.
    target : str
        Ground-truth force stream (N), sampled with the input stream.
    axes : sequence of str
        Its channels to predict.
    baseline : {"first", "none"}
        ``"first"``: subtract from every electrode (and pdc) value the median of its
        trial's first ``baseline_frames`` frames, the unloaded reading, so inputs are
        the impedance *changes* ``E_i`` of the paper (the simulated probe starts
        every trial at rest). ``"none"``: raw counts (the weighted-normals model's
        offset then absorbs the baseline).
    baseline_frames : int
        Frames at the start of each trial that define the baseline.
    block_s : float
        Block length (s) of the split; a trial shorter than this is one block.
    test_size, val_size : float
        Fractions of blocks held out for test, and of the training blocks for the
        networks' early stopping (paper: 0.2 and 0.2).
    stride : int
        Keep every ``stride``-th frame of each trial (after splitting) to shorten
        training; 1 keeps all.
    model_name : str
        Row name of the main model in the comparison.
    compare : mapping or list, optional
        Further models (``_target_`` nodes or estimators; a mapping gives their
        names) fitted on the same split and written to ``comparison.csv/.md``.
    plot_s : float
        Length (s) of the test stretch drawn in ``force_test.png``.
    cv : int
        Folds of the validation score (the run's objective, ``validation.rmse_mean``):
        the main model refitted by ``GroupKFold`` over the training side's blocks
        (train + val), each block held out once; never the test blocks. 0 or 1: none
        (the objective is then missing).
    """

    accepts = (_RegressorMixin,)
    refuses = analytic_estimators()
    feeds = "fits a learned regressor on frames of stream {stream}"

    objective = "validation.rmse_mean"
    direction = "minimize"

    def __init__(
        self,
        *,
        stream: str = "electrodes",
        pdc_stream: str | None = None,
        target: str = "truth_force",
        axes: Sequence[str] = ("fx", "fy", "fz"),
        baseline: str = "first",
        baseline_frames: int = 10,
        block_s: float = 30.0,
        test_size: float = 0.2,
        val_size: float = 0.2,
        stride: int = 1,
        model_name: str = "model",
        compare: Any = None,
        plot_s: float = 10.0,
        cv: int = 3,
    ) -> None:
        self.stream = stream
        self.pdc_stream = pdc_stream
        self.target = target
        self.axes = axes
        self.baseline = baseline
        self.baseline_frames = baseline_frames
        self.block_s = block_s
        self.test_size = test_size
        self.val_size = val_size
        self.stride = stride
        self.model_name = model_name
        self.compare = compare
        self.plot_s = plot_s
        self.cv = cv

    # -- data -----------------------------------------------------------------------
    def frames(self, dataset: Dataset) -> Frames:
        """Aligned (X, y) of every frame of ``dataset`` (before the stride)."""
        if self.baseline not in ("first", "none"):
            raise SlipkitError(
                f"task.baseline must be 'first' or 'none'; got {self.baseline!r}"
            )
        table = _stream(dataset, self.stream)
        channels = _channels(dataset, self.stream, None)
        X = table[channels].to_numpy(dtype=np.float64)
        if self.baseline == "first":
            X = X - _first_frames_median(table, channels, int(self.baseline_frames))
        merged, axes = _target_rows(dataset, table, self.target, self.axes)
        row = merged["_row"].to_numpy()
        X = X[row]
        if self.pdc_stream is not None:
            ptab = _stream(dataset, self.pdc_stream)
            pch = _channels(dataset, self.pdc_stream, None)
            if self.baseline == "first":
                ptab = ptab.copy()
                ptab[pch] = ptab[pch].to_numpy(dtype=np.float64) - _first_frames_median(
                    ptab, pch, int(self.baseline_frames)
                )
            withp = _join(merged[["trial_id", "t", "_row"]], ptab, pch, self.pdc_stream)
            keep = np.isin(row, withp["_row"].to_numpy())
            merged, X, row = merged[keep], X[keep], row[keep]
            X = np.column_stack([X, withp[pch].to_numpy(dtype=np.float64)])
        return Frames(
            X=X,
            y=merged[axes].to_numpy(dtype=np.float64),
            t=merged["t"].to_numpy(dtype=np.float64),
            trial=merged["trial_id"].astype(str).to_numpy(),
            row=row,
        )

    def _strided(self, frames: Frames) -> np.ndarray:
        """Mask keeping every ``stride``-th frame of each trial."""
        if int(self.stride) < 1:
            raise SlipkitError(f"task.stride must be >= 1; got {self.stride}")
        pos = pd.Series(frames.trial).groupby(frames.trial, sort=False).cumcount()
        return np.asarray(pos.to_numpy() % int(self.stride) == 0)

    def score(
        self, pred: np.ndarray, frames: Frames, mask: np.ndarray
    ) -> dict[str, Any]:
        """RMSE (N) and SMSE per axis, and their means, over the frames in ``mask``."""
        names = [_axis(a) for a in self.axes]
        return _with_means(regression_metrics(frames.y[mask], pred[mask], names))

    # -- fit --------------------------------------------------------------------------
    def sides(
        self, dataset: Dataset, frames: Frames, *, seed: int
    ) -> tuple[Sides, np.ndarray]:
        """Train / val / test masks over ``frames`` (30 s blocks, then the stride) and
        the block id of every frame."""
        try:
            split = split_time_blocks(
                dataset,
                self.stream,
                block_s=float(self.block_s),
                test_size=float(self.test_size),
                val_size=float(self.val_size),
                seed=seed,
            )
        except ValueError as exc:
            raise SlipkitError(
                f"{exc} (task.block_s={self.block_s}: simulate more or longer trials, "
                "or shorten the blocks)"
            ) from None
        keep = self._strided(frames)
        sides = Sides(
            train=keep & np.isin(frames.row, split.train),
            val=keep & np.isin(frames.row, split.val),
            test=keep & np.isin(frames.row, split.test),
        )
        return sides, split.blocks[frames.row]

    def fit(self, model: Any, dataset: Dataset, *, seed: int, out: Path) -> TaskResult:
        frames = self.frames(dataset)
        sides, block = self.sides(dataset, frames, seed=seed)
        full = sides.train | sides.val | sides.test
        n_blocks = {
            side: len(np.unique(block[mask]))
            for side, mask in (
                ("train", sides.train),
                ("val", sides.val),
                ("test", sides.test),
            )
        }
        durations = (
            pd.Series(frames.t).groupby(frames.trial).agg(lambda s: s.max() - s.min())
        )
        blocks_are_trials = bool(durations.max() < float(self.block_s))
        log.info(
            "frames: %d train / %d val / %d test (blocks %s, %s s)",
            sides.train.sum(),
            sides.val.sum(),
            sides.test.sum(),
            n_blocks,
            self.block_s,
        )
        validation = (
            {"cv": f"group-kfold by {float(self.block_s):g} s block"}
            | _block_cv(
                model,
                frames,
                np.flatnonzero(sides.train | sides.val),
                block,
                int(self.cv),
                lambda p, idx: self.score(p, frames, idx)["rmse_mean"],
                "rmse_mean",
                "force validation",
            )
            if int(self.cv) > 1
            else None
        )
        models = {str(self.model_name): model, **_compare_models(self.compare)}
        preds: dict[str, np.ndarray] = {}
        fitted_on: dict[str, str] = {}
        for name, est in models.items():
            log.info("fitting %s (%s)", name, type(est).__name__)
            fitted_on[name] = _fit_with_val(est, frames.X, frames.y, sides)
            preds[name] = np.asarray(est.predict(frames.X)).reshape(frames.y.shape)
        main = preds[str(self.model_name)]
        metrics: dict[str, Any] = {
            "model": str(self.model_name),
            "inputs": {
                "stream": self.stream,
                "pdc_stream": self.pdc_stream,
                "n_features": int(frames.X.shape[1]),
                "baseline": self.baseline,
                "stride": int(self.stride),
            },
            "split": {
                "block_s": float(self.block_s),
                "blocks": n_blocks,
                "blocks_are_trials": blocks_are_trials,
                "frames": {
                    "train": int(sides.train.sum()),
                    "val": int(sides.val.sum()),
                    "test": int(sides.test.sum()),
                },
            },
            "fit": {**_fit_info(model), "fitted_on": fitted_on[str(self.model_name)]},
            "validation": validation,
            "full": self.score(main, frames, full),
            "train": self.score(main, frames, sides.train),
            "val": self.score(main, frames, sides.val) if sides.val.any() else None,
            "test": self.score(main, frames, sides.test),
            "paper_test_3layer": PAPER_TEST,
        }
        rows = {}
        comparison: dict[str, Any] = {}
        for name, est in models.items():
            m_full = self.score(preds[name], frames, full)
            m_test = self.score(preds[name], frames, sides.test)
            comparison[name] = {
                "fit": {**_fit_info(est), "fitted_on": fitted_on[name]},
                "full": m_full,
                "test": m_test,
            }
            rows[name] = _comparison_row(m_full, m_test)
        metrics["comparison"] = comparison
        table = pd.DataFrame.from_dict(rows, orient="index")
        table.index.name = "model"
        table.to_csv(out / "comparison.csv")
        paper = pd.DataFrame.from_dict(
            {"paper 3-layer NN (Su et al. 2015)": _paper_row(list(table.columns))},
            orient="index",
        )
        (out / "comparison.md").write_text(
            "# Force regression: RMSE (N) and SMSE per axis, full set and test set\n\n"
            + _markdown(pd.concat([table, paper]).rename_axis("model"))
            + "\nThe paper row gives its published test figures only (Sec. V-A).\n",
            encoding="utf-8",
        )
        self._plot(frames, preds, sides.test, out / "force_test.png", "test")
        metrics["ranking"] = _ranking(comparison)
        summary = _summary(metrics)
        if validation is not None:
            summary.insert(
                1,
                f"  validation ({validation['cv']}, k={validation['k']}, training side "
                f"only): {self.model_name} mean RMSE {validation['rmse_mean']:.3f} N",
            )
        if blocks_are_trials:
            summary.insert(
                1,
                f"  (trials are shorter than {self.block_s:g} s: each block is a whole trial)",
            )
        return TaskResult(model, metrics, summary)

    def evaluate(self, model: Any, dataset: Dataset, *, out: Path) -> dict[str, Any]:
        """RMSE / SMSE over every (strided) frame of ``dataset`` as ``test``, and a plot
        of its first trial (``force_test.png``)."""
        frames = self.frames(dataset)
        keep = self._strided(frames)
        pred = np.asarray(model.predict(frames.X)).reshape(frames.y.shape)
        self._plot(
            frames,
            {str(self.model_name): pred},
            keep,
            out / "force_test.png",
            "dataset",
        )
        return {"model": str(self.model_name), "test": self.score(pred, frames, keep)}

    # -- plot -------------------------------------------------------------------------
    def _plot(
        self,
        frames: Frames,
        preds: Mapping[str, np.ndarray],
        mask: np.ndarray,
        path: Path,
        what: str,
    ) -> None:
        """Truth and predictions over the first ``plot_s`` s of the first trial in ``mask``."""
        from matplotlib.figure import Figure  # no pyplot: no global backend state

        idx = np.flatnonzero(mask)
        if len(idx) == 0:
            return
        tid = frames.trial[idx[0]]
        sel = idx[frames.trial[idx] == tid]
        t0 = frames.t[sel[0]]
        sel = sel[(frames.t[sel] >= t0) & (frames.t[sel] <= t0 + float(self.plot_s))]
        fig = Figure(figsize=(9, 2.2 * len(self.axes)), layout="constrained")
        axs = fig.subplots(len(self.axes), 1, sharex=True, squeeze=False)[:, 0]
        for k, (ax, name) in enumerate(zip(axs, self.axes, strict=True)):
            ax.plot(frames.t[sel], frames.y[sel, k], color="black", lw=2, label="truth")
            for model, p in preds.items():
                ax.plot(frames.t[sel], p[sel, k], lw=1, label=model)
            ax.set_ylabel(f"{name} (N)")
        axs[0].set_title(f"force, {what} trial {tid}")
        axs[0].legend(loc="upper right", fontsize="small", ncols=min(len(preds) + 1, 5))
        axs[-1].set_xlabel("t (s)")
        fig.savefig(path, dpi=100)


def _block_cv(
    model: Any,
    frames: Frames,
    rows: np.ndarray,
    groups: np.ndarray,
    k: int,
    score: Any,
    name: str,
    label: str,
) -> dict[str, Any]:
    """``GroupKFold`` over ``groups[rows]`` (training-side frames only): clones of
    ``model`` fitted on k-1 folds, ``score(pred, mask)`` on the held-out fold."""
    from sklearn.model_selection import GroupKFold

    n_groups = len(np.unique(groups[rows]))
    if n_groups < k:
        raise SlipkitError(
            f"task.cv={k}: the training side has only {n_groups} blocks; lower task.cv"
        )
    folds: list[float] = []
    start = time.perf_counter()
    splitter = GroupKFold(n_splits=k)
    for i, (a, b) in enumerate(splitter.split(rows, groups=groups[rows])):
        est = clone(model).fit(frames.X[rows[a]], frames.y[rows[a]])
        pred = np.asarray(est.predict(frames.X)).reshape(frames.y.shape)
        mask = np.zeros(len(frames.y), dtype=bool)
        mask[rows[b]] = True
        folds.append(float(score(pred, mask)))
        elapsed = time.perf_counter() - start
        progress_line(
            f"{label}: fold {i + 1}/{k} done, {elapsed:.0f} s elapsed, ETA "
            f"{elapsed / (i + 1) * (k - i - 1):.0f} s"
        )
    return {
        "k": k,
        "scoring": name,
        name: float(np.mean(folds)),
        "std": float(np.std(folds)),
        "folds": folds,
    }


def _stream_name(dataset: Dataset, name: str) -> str:
    if name not in dataset.streams:
        raise SlipkitError(
            f"dataset {dataset.name or dataset.sensor!r} has no stream {name!r}; "
            f"streams: {sorted(dataset.streams)}"
        )
    return name


def _comparison_row(
    m_full: Mapping[str, Any], m_test: Mapping[str, Any]
) -> dict[str, float]:
    row: dict[str, float] = {}
    for side, m in (("full", m_full), ("test", m_test)):
        for metric in ("rmse", "smse"):
            for axis, value in m[metric].items():
                row[f"{metric}_{axis}_{side}"] = float(value)
    return row


def _paper_row(columns: list[str]) -> dict[str, float]:
    row = dict.fromkeys(columns, float("nan"))
    for metric, values in PAPER_TEST.items():
        for axis, v in values.items():
            key = f"{metric}_{axis}_test"
            if key in row:
                row[key] = v
    return row


def _fmt3(values: Mapping[str, float], fmt: str) -> str:
    return " ".join(format(v, fmt) for v in values.values())


def _ranking(comparison: Mapping[str, Any]) -> dict[str, Any]:
    """Which model has the lowest mean SMSE on the full set and on the test set: the
    paper found the 1-layer network and LWPR best on the full set, the 3-layer network
    best on the test set (Fig. 6)."""
    full = {n: c["full"]["smse_mean"] for n, c in comparison.items()}
    test = {n: c["test"]["smse_mean"] for n, c in comparison.items()}
    return {
        "by": "smse_mean",
        "best_full": min(full, key=full.__getitem__),
        "best_test": min(test, key=test.__getitem__),
        "full_order": sorted(full, key=full.__getitem__),
        "test_order": sorted(test, key=test.__getitem__),
    }


def _summary(metrics: Mapping[str, Any]) -> list[str]:
    sp = metrics["split"]
    lines = [
        f"BioTac force regression, {sp['block_s']:g} s blocks "
        f"(train {sp['blocks']['train']} / val {sp['blocks']['val']} / test "
        f"{sp['blocks']['test']}; frames {sp['frames']['train']} / "
        f"{sp['frames']['val']} / {sp['frames']['test']})",
        f"  {'model':<12} {'full RMSE x y z (N)':>20} {'full SMSE x y z':>17}  "
        f"{'test RMSE x y z (N)':>20} {'test SMSE x y z':>17}",
    ]
    for name, c in metrics["comparison"].items():
        lines.append(
            f"  {name:<12} {_fmt3(c['full']['rmse'], '6.3f'):>20} "
            f"{_fmt3(c['full']['smse'], '5.3f'):>17}  "
            f"{_fmt3(c['test']['rmse'], '6.3f'):>20} {_fmt3(c['test']['smse'], '5.3f'):>17}"
        )
    lines.append(
        f"  {'paper 3-NN':<12} {'-':>20} {'-':>17}  "
        f"{_fmt3(PAPER_TEST['rmse'], '6.3f'):>20} {_fmt3(PAPER_TEST['smse'], '5.3f'):>17}"
    )
    rank = metrics["ranking"]
    if len(rank["full_order"]) > 1:
        lines.append(
            f"  mean SMSE order, full: {' < '.join(rank['full_order'])}; test: "
            f"{' < '.join(rank['test_order'])} (paper: 1-layer NN and LWPR best on "
            "full, 3-layer NN best on test)"
        )
    return lines


__all__: Sequence[str] = ["ForceRegression"]
