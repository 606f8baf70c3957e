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
import sys
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from sklearn.base import clone

from slipkit.data.dataset import Dataset
from slipkit.data.splits import split_by_group, split_by_trial, split_time_blocks
from slipkit.errors import SlipkitError
from slipkit.evaluate.metrics import regression_metrics
from slipkit.train.task import Task, TaskResult

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
        print(
            f"{label}: fold {i + 1}/{k} done, {elapsed:.0f} s elapsed, ETA "
            f"{elapsed / (i + 1) * (k - i - 1):.0f} s",
            file=sys.stderr,
            flush=True,
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


__all__: Sequence[str] = [
    "FingerDirection",
    "ForceRegression",
    "angle_errors_deg",
    "contiguous_block_split",
]
