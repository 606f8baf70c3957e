"""Per-trial scores of the GelSight detectors and controls, split by object (nested CV).

``python -m slipkit.families.gelsight.report <imported dataset> [--seeds 0 1 2]``

For each seed the objects are dealt into ``outer`` folds (group k-fold, shuffled by the
seed). For each outer fold, every candidate setting of a detector is scored on the
training side by an inner group k-fold (``inner`` folds): out-of-fold trial scores, the
threshold of best balanced accuracy on them (:func:`~slipkit.families.gelsight.detectors.choose_threshold`),
and that balanced accuracy. The best setting is refitted on the whole training side,
its threshold taken from the out-of-fold scores, and the held-out objects' trials are
scored once. Per seed the held-out trials of all folds are pooled: balanced accuracy
(trial = slip when the detector ever fires), the same on the full-length trials alone
(recordings that did not stop early, where clip length carries no label), slip
recall, wiggle false-alarm rate and the frame of first alarm; the table gives mean and
sd over seeds.

``--split-of RUN [RUN ...]`` scores instead on the train / test split of ``slipkit
train`` run folders (one per seed: the setting and threshold chosen by inner group CV
on the run's training objects, its test objects scored once) and prints each run's own
test trial events beside them: the controls next to a deployed detector.

``--arm`` sets when the whole-recording detectors are armed; the contact-phase ones
(``divergence_contact``, ``contact_motion``, ``contact_logistic``) are armed at :data:`CONTACT_ARMS`, so their
displacement reference is the start of contact.
"""

from __future__ import annotations

import argparse
import json
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from sklearn.model_selection import GroupKFold

from slipkit._files import check_out_file, read_json_object, write_out_file
from slipkit.data.dataset import Dataset
from slipkit.errors import SlipkitError
from slipkit.families.gelsight.detectors import (
    ClipLengthControl,
    FirstFramesControl,
    MajorityControl,
    PinMotionDetector,
    TacTipVelocityDetector,
    Trial,
    WindowModelDetector,
    choose_threshold,
)
from slipkit.families.gelsight.importer import FINGERTIPS

Factory = Callable[[], Any]

#: arming frames of the contact-phase detectors: the displacement reference is the
#: first armed frame, so the marker jump that opens slip clips (frames 3-10) is read
CONTACT_ARMS = (3, 4)
#: frames after arming that ``contact_motion`` watches (None: the whole recording)
CONTACT_HORIZONS = (50, 100, 150, 200, 250, None)


@dataclass(frozen=True)
class Candidate:
    """A detector and the settings its inner CV chooses among."""

    name: str
    settings: tuple[tuple[str, Factory], ...]
    kind: str = "detector"  # or "control"


def _contact_settings(fingers: Sequence[str]) -> tuple[tuple[str, Factory], ...]:
    """``contact_motion``'s settings: quantity x horizon x how fingertips combine."""
    return tuple(
        (
            f"{q} h{h} {f}",
            partial(
                PinMotionDetector,
                quantity=q,
                window=50,
                arm=CONTACT_ARMS[0],
                horizon=h,
                fingers=f,
            ),
        )
        for q in ("divergence", "contraction", "divergence_per_path")
        for h in CONTACT_HORIZONS
        for f in fingers
    )


def candidates(seed: int, arm: int = 12) -> list[Candidate]:
    """Every detector and control of the report, with their settings (the streaming
    detectors armed ``arm`` frames into a recording)."""
    return [
        Candidate(
            "pin_motion",
            tuple(
                (f"{q} w{w}", partial(PinMotionDetector, quantity=q, window=w, arm=arm))
                for q in PinMotionDetector.QUANTITIES
                for w in (25, 50)
            ),
        ),
        Candidate(
            "divergence_contact",
            tuple(
                (
                    f"arm{a} w{w}",
                    partial(PinMotionDetector, quantity="divergence", window=w, arm=a),
                )
                for a in CONTACT_ARMS
                for w in (25, 50)
            ),
        ),
        Candidate("contact_motion", _contact_settings(("max", "min"))),
        Candidate("contact_motion_one", _contact_settings(("first",))),
        Candidate(
            "window_logistic",
            tuple(
                (
                    f"C{c} w{w} top{top}",
                    partial(
                        WindowModelDetector, C=c, window=w, top=top, arm=arm, seed=seed
                    ),
                )
                for c in (0.01, 1.0)
                for w in (25, 50)
                for top in (1.0, 0.1)
            ),
        ),
        Candidate(
            "contact_logistic",
            tuple(
                (
                    f"C{c} top{top} h{h}",
                    partial(
                        WindowModelDetector,
                        C=c,
                        window=50,
                        top=top,
                        arm=CONTACT_ARMS[0],
                        horizon=h,
                        step=3,
                        seed=seed,
                    ),
                )
                for c in (0.01, 1.0)
                for top in (1.0, 0.2)
                for h in (100, 200)
            ),
        ),
        Candidate(
            "window_svm",
            tuple(
                (
                    f"C{c} w{w}",
                    partial(
                        WindowModelDetector,
                        model="svm",
                        arm=arm,
                        C=c,
                        window=w,
                        step=10,
                        seed=seed,
                    ),
                )
                for c in (0.3, 3.0)
                for w in (50,)
            ),
        ),
        Candidate(
            "tactip_svm",
            tuple(
                (
                    f"C{c} smooth{k}",
                    partial(
                        TacTipVelocityDetector,
                        C=c,
                        smooth=k,
                        step=10,
                        arm=arm,
                        seed=seed,
                    ),
                )
                for c in (1.0,)
                for k in (10, 25)
            ),
        ),
        Candidate("clip_length", (("", ClipLengthControl),), "control"),
        Candidate("first_frames", (("", FirstFramesControl),), "control"),
        Candidate("majority", (("", MajorityControl),), "control"),
    ]


def load_trials(
    dataset: Dataset,
) -> tuple[list[Trial], np.ndarray, np.ndarray, list[str]]:
    """Trials (fingertip -> pin rows), labels, groups and ids of an imported dataset
    (each fingertip's own stream; the side-by-side ``fingertips`` stream is left out)."""
    streams = sorted(s for s in dataset.streams if s != FINGERTIPS)
    trials: list[Trial] = []
    ys: list[int] = []
    groups: list[str] = []
    ids: list[str] = []
    for trial in dataset:
        trials.append(
            {
                s: trial.streams[s][list(dataset.streams[s].channels)].to_numpy(
                    np.float64
                )
                for s in streams
            }
        )
        ys.append(int(trial.labels["slipped"]))
        groups.append(str(trial.meta["object"]))
        ids.append(trial.trial_id)
    return trials, np.asarray(ys), np.asarray(groups), ids


def _oof_scores(
    factory: Factory,
    trials: Sequence[Trial],
    y: np.ndarray,
    g: np.ndarray,
    folds: int,
    seed: int,
) -> np.ndarray:
    out = np.empty(len(trials))
    cv = GroupKFold(n_splits=min(folds, len(set(g))), shuffle=True, random_state=seed)
    for tr, te in cv.split(np.zeros(len(y)), y, g):
        det = factory().fit([trials[i] for i in tr], y[tr])
        out[te] = [det.trial_score(trials[i]) for i in te]
    return out


def _ba(fired: np.ndarray, y: np.ndarray) -> float:
    return float((fired[y == 1].mean() + (~fired[y == 0]).mean()) / 2)


def choose_setting(
    cand: Candidate,
    trials: Sequence[Trial],
    y: np.ndarray,
    g: np.ndarray,
    *,
    seed: int,
    inner: int = 4,
) -> tuple[str, Any]:
    """The setting of ``cand`` with the best balanced accuracy on out-of-fold trial
    scores of an inner group k-fold over ``trials``, refitted on all of them, its
    threshold chosen on those out-of-fold scores: (setting label, fitted detector)."""
    best: tuple[float, str, Factory, float] | None = None
    for label, factory in cand.settings:
        s = _oof_scores(factory, trials, y, g, inner, seed)
        thr = choose_threshold(s.tolist(), y.tolist())
        ba = _ba(s >= thr, y)
        if best is None or ba > best[0]:
            best = (ba, label, factory, thr)
    assert best is not None
    _, label, factory, thr = best
    det = factory().fit(list(trials), y)
    det.threshold_ = thr
    return label, det


def full_length(trials: Sequence[Trial]) -> np.ndarray:
    """Which trials run as long as the longest one: the recordings that did not stop
    early, where clip length says nothing about the label."""
    n = np.array([max(len(f) for f in t.values()) for t in trials])
    return n >= n.max()


def pooled(
    fired: np.ndarray,
    first: np.ndarray,
    y: np.ndarray,
    full: np.ndarray | None = None,
) -> dict[str, float]:
    """Balanced accuracy, slip recall, wiggle false alarms and the median first-alarm
    frames of trial calls ``fired`` (first alarm frame ``first``, NaN: none); with
    ``full`` (:func:`full_length`), the balanced accuracy on full-length trials alone
    (NaN without both classes among them)."""
    slip, wig = y == 1, y == 0
    ba_full = math.nan
    if full is not None and len(set(y[full].tolist())) == 2:
        ba_full = _ba(fired[full], y[full])
    return {
        "balanced_accuracy": _ba(fired, y),
        "balanced_accuracy_full_length": ba_full,
        "slip_recall": float(fired[slip].mean()),
        "wiggle_false_alarm": float(fired[wig].mean()),
        "first_alarm_frame_slip": float(np.nanmedian(first[slip & fired]))
        if (slip & fired).any()
        else math.nan,
        "first_alarm_frame_wiggle": float(np.nanmedian(first[wig & fired]))
        if (wig & fired).any()
        else math.nan,
    }


def evaluate(
    cand: Candidate,
    trials: Sequence[Trial],
    y: np.ndarray,
    g: np.ndarray,
    *,
    seed: int,
    outer: int = 5,
    inner: int = 4,
) -> dict[str, Any]:
    """Nested group CV of one detector for one seed (see the module doc)."""
    cv = GroupKFold(n_splits=outer, shuffle=True, random_state=seed)
    folds = list(cv.split(np.zeros(len(y)), y, g))
    return _score_folds(cand, trials, y, g, folds, seed=seed, inner=inner)


def _score_folds(
    cand: Candidate,
    trials: Sequence[Trial],
    y: np.ndarray,
    g: np.ndarray,
    folds: Sequence[tuple[np.ndarray, np.ndarray]],
    *,
    seed: int,
    inner: int,
) -> dict[str, Any]:
    """Fit on each fold's training trials (:func:`choose_setting`), score its test trials
    once; the pooled test trials' rates."""
    scored = np.zeros(len(y), dtype=bool)
    fired = np.zeros(len(y), dtype=bool)
    first = np.full(len(y), np.nan)
    chosen: list[str] = []
    for tr, te in folds:
        label, det = choose_setting(
            cand, [trials[i] for i in tr], y[tr], g[tr], seed=seed, inner=inner
        )
        chosen.append(label)
        for i in te:
            a = det.alarm(trials[i])
            scored[i] = True
            fired[i] = a is not None
            first[i] = np.nan if a is None else a
    full = full_length(trials)
    return {
        **pooled(fired[scored], first[scored], y[scored], full[scored]),
        "chosen": chosen,
    }


def _nan_stat(fn: Callable[..., Any], values: Sequence[float]) -> float:
    """``fn`` over the finite values (NaN when there are none: e.g. no alarm at all)."""
    v = np.asarray(values, dtype=np.float64)
    return float(fn(v)) if np.isfinite(v).any() else math.nan


def run(
    dataset: Dataset,
    seeds: Sequence[int],
    names: Sequence[str] | None = None,
    *,
    arm: int = 12,
) -> dict[str, Any]:
    """Every detector and control over ``seeds``: per-seed results and mean / sd."""
    trials, y, g, _ = load_trials(dataset)
    out: dict[str, Any] = {
        "trials": len(y),
        "slip": int(y.sum()),
        "objects": len(set(g)),
        "seeds": [int(s) for s in seeds],
    }
    rows: dict[str, Any] = {}
    for cand in candidates(0, arm):
        if names and cand.name not in names:
            continue
        per_seed = []
        for seed in seeds:
            c = next(c for c in candidates(seed, arm) if c.name == cand.name)
            per_seed.append(evaluate(c, trials, y, g, seed=seed))
        keys = [k for k in per_seed[0] if k != "chosen"]
        rows[cand.name] = {
            "kind": cand.kind,
            **{
                k: {
                    "mean": _nan_stat(np.nanmean, [r[k] for r in per_seed]),
                    "sd": _nan_stat(np.nanstd, [r[k] for r in per_seed]),
                }
                for k in keys
            },
            "per_seed": per_seed,
        }
        print(_row(cand.name, rows[cand.name]), flush=True)
    out["results"] = rows
    return out


def run_split(
    dataset: Dataset,
    runs: Sequence[Path],
    names: Sequence[str] | None = None,
    *,
    arm: int = 12,
    inner: int = 4,
) -> dict[str, Any]:
    """Every detector and control on the train / test split of each run folder (a
    ``slipkit train`` run on this dataset: ``metrics.json`` ``split``), the setting and
    threshold chosen by inner group CV on its training trials, its test trials scored
    once; beside them each run's own test trial events (``test.operating_point``)."""

    trials, y, g, ids = load_trials(dataset)
    index = {t: i for i, t in enumerate(ids)}
    full = full_length(trials)
    hz = next(iter(dataset.streams.values())).rate_hz
    rate = float(hz) if hz else math.nan  # no rate: no first-alarm frame
    rows: dict[str, Any] = {}
    per_run: list[dict[str, Any]] = []
    splits = []
    for path in runs:
        metrics_path = Path(path) / "metrics.json"
        try:
            m = json.loads(metrics_path.read_text())
            split = m["split"]
            seed = int(json.loads((Path(path) / "run.json").read_text())["seed"])
            tr = np.array([index[str(t)] for t in split["train"]])
            te = np.array([index[str(t)] for t in split["test"]])
        except (OSError, ValueError, KeyError) as exc:
            raise SlipkitError(
                f"{metrics_path}: not a run of this dataset with a split ({exc})"
            ) from None
        splits.append((seed, tr, te))
        op = m["test"]["operating_point"]
        chosen = [f"{m['name']}: debounce {op['debounce_k']}"]
        per_run.append(
            {**_run_trials(Path(path), index, y, full, rate), "chosen": chosen}
        )
    groups = [("run", "deployed", per_run)]
    for cand in candidates(0, arm):
        if names and cand.name not in names:
            continue
        per_seed = []
        for seed, tr, te in splits:
            c = next(c for c in candidates(seed, arm) if c.name == cand.name)
            per_seed.append(
                _score_folds(c, trials, y, g, [(tr, te)], seed=seed, inner=inner)
            )
        groups.append((cand.name, cand.kind, per_seed))
    for name, kind, per_seed in groups:
        keys = [k for k in per_seed[0] if k != "chosen"]
        rows[name] = {
            "kind": kind,
            **{
                k: {
                    "mean": _nan_stat(np.nanmean, [r[k] for r in per_seed]),
                    "sd": _nan_stat(np.nanstd, [r[k] for r in per_seed]),
                }
                for k in keys
            },
            "per_seed": per_seed,
        }
        print(_row(name, rows[name]), flush=True)
    return {"runs": [str(p) for p in runs], "results": rows}


def _run_trials(
    run: Path, index: dict[str, int], y: np.ndarray, full: np.ndarray, rate: float
) -> dict[str, float]:
    """A run's own test trial events (``test_trials.csv``: the deployed detector's
    alarms at its operating point) as :func:`pooled` rates over those trials."""
    path = run / "test_trials.csv"
    try:
        t = pd.read_csv(path)
        at = np.array([index[str(i)] for i in t["trial_id"]])
        fired = t["n_alarms"].to_numpy() > 0
        first = t["first_alarm_s"].to_numpy(np.float64) * rate
    except (OSError, ValueError, KeyError) as exc:
        raise SlipkitError(
            f"{path}: not the test trials of this dataset ({exc})"
        ) from None
    return pooled(fired, np.round(first), y[at], full[at])


def _is_results(path: Path) -> bool:
    """Whether ``path`` holds results this module wrote (a JSON object with
    ``results``): what ``--out`` may replace."""
    obj = read_json_object(path)
    return obj is not None and "results" in obj


def check_json_out(out: str | None, inputs: dict[str, str | None]) -> Path | None:
    """``--out`` checked before any work by the out-file rule
    (:func:`slipkit._files.check_out_file`): not an input, not inside a dataset, run or
    bundle, and an existing file only when it holds earlier results."""
    if not out:
        return None
    return check_out_file(
        out, option="--out", inputs=inputs, is_own=_is_results, what="GelSight results"
    )


def write_json_out(
    path: Path, res: dict[str, Any], inputs: dict[str, str | None]
) -> None:
    """Write ``res`` to ``--out`` (checked again, then written atomically)."""
    write_out_file(
        path,
        json.dumps(res, indent=2),
        option="--out",
        inputs=inputs,
        is_own=_is_results,
        what="GelSight results",
    )


def _row(name: str, r: dict[str, Any]) -> str:
    def ms(k: str, d: int = 2) -> str:
        if not math.isfinite(r[k]["mean"]):
            return "n/a"
        return f"{r[k]['mean']:.{d}f} +- {r[k]['sd']:.{d}f}"

    return (
        f"| {name} | {r['kind']} | {ms('balanced_accuracy')} | "
        f"{ms('balanced_accuracy_full_length')} | {ms('slip_recall')} | "
        f"{ms('wiggle_false_alarm')} | {r['first_alarm_frame_slip']['mean']:.0f} |"
    )


def main(argv: Sequence[str] | None = None) -> None:
    from slipkit.data.io import load_dataset

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument(
        "dataset", help="a dataset folder written by slipkit import source=gelsight"
    )
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    ap.add_argument("--only", nargs="*", help="detector names (default: all)")
    ap.add_argument("--out", help="write the results as JSON here")
    ap.add_argument(
        "--arm",
        type=int,
        default=12,
        help="frames before the detectors are armed (12: 0.5 s)",
    )
    ap.add_argument(
        "--split-of",
        nargs="+",
        metavar="RUN",
        help="score on the train / test split of these slipkit train run folders "
        "(one per seed) instead of nested CV, beside the runs' own test events",
    )
    args = ap.parse_args(argv)
    print(
        "| detector | kind | balanced accuracy | full-length clips | slip recall "
        "| wiggle false alarms | first alarm (frame) |"
    )
    print("|---|---|---|---|---|---|---|")
    inputs: dict[str, str | None] = {"dataset": args.dataset}
    out = check_json_out(args.out, inputs)
    data = load_dataset(args.dataset)
    res = (
        run_split(data, [Path(p) for p in args.split_of], args.only, arm=args.arm)
        if args.split_of
        else run(data, args.seeds, args.only, arm=args.arm)
    )
    if out is not None:
        write_json_out(out, res, inputs)


if __name__ == "__main__":  # pragma: no cover
    main()
