"""BTS3v2 grasp stability per palm orientation: fixed candidates on held-out objects.

No selection here: every candidate has fixed parameters (the model configs'
defaults), is fitted on the training objects and scored once on the held-out ones.
Per seed, 10 of the 41 objects are held out (``split_by_group``, ``test_size`` 0.24,
as ``slipkit train experiment=bts3v2_stability seed=<s>``), and each candidate is
scored three ways, balanced accuracy overall and per orientation:

* **held out**: the held-out objects as recorded;
* **baseline shift**: the same grasps with, per orientation, an offset added to each
  finger pad (normal, sd ``--finger`` counts) and to each electrode (sd
  ``--electrode`` counts): a sensor baseline that moved between recording sessions;
* **orientation left out**: fitted on the training objects' grasps in two
  orientations, scored on the held-out objects in the third (no one-hot, no
  per-orientation statistics: only the handlings that need no orientation).

Besides every family with every orientation handling, "one per orientation" fits a
separate ``shape`` model on each orientation's training grasps. First it prints the
mean reading per finger pad and orientation (all grasps), the stable - slipped
difference, and the mean of each fifth of a file (file order): how far orientation,
class and recording time move the baseline.

    .venv/bin/python benchmarks/bench_grasp_orientation.py --seeds 5
"""

from __future__ import annotations

import argparse
import json
import os
from pathlib import Path
from typing import Any

import numpy as np
from sklearn.base import clone
from sklearn.linear_model import LogisticRegression
from sklearn.metrics import balanced_accuracy_score
from sklearn.neural_network import MLPClassifier
from sklearn.pipeline import make_pipeline
from sklearn.preprocessing import StandardScaler
from sklearn.svm import SVC

from slipkit.data.importers.bts3v2 import read_bts3v2
from slipkit.data.splits import split_by_group
from slipkit.families.biotac.grasp_task import GraspStability, grasp_pipeline

ORIENTATIONS = ("palm_down", "palm_side", "palm_45")
#: The configs' defaults (configs/model/grasp_*.yaml).
FAMILIES: dict[str, Any] = {
    "logreg": LogisticRegression(C=1.0, max_iter=5000),
    "svm": SVC(C=10.0, gamma="scale"),
    "mlp": MLPClassifier(
        hidden_layer_sizes=(64,),
        alpha=1e-3,
        learning_rate_init=1e-3,
        max_iter=300,
        early_stopping=True,
        random_state=0,
    ),
}
MODES = ("none", "orientation_feature", "per_orientation", "per_grasp", "shape")
#: Orientation handlings that need no orientation (for "orientation left out").
BLIND = ("none", "per_grasp", "shape")


def _scores(y: np.ndarray, pred: np.ndarray, ori: np.ndarray) -> dict[str, float]:
    out = {"all": float(balanced_accuracy_score(y, pred))}
    for o in ORIENTATIONS:
        if (ori == o).any():
            out[o] = float(balanced_accuracy_score(y[ori == o], pred[ori == o]))
    return out


class PerOrientation:
    """One clone of ``pipe`` per orientation, each fitted on that orientation's rows."""

    def __init__(self, pipe: Any, ori: np.ndarray) -> None:
        self.pipe, self.ori = pipe, ori

    def fit(self, X: np.ndarray, y: np.ndarray, rows: np.ndarray) -> PerOrientation:
        self.models_ = {
            o: clone(self.pipe).fit(X[self.ori[rows] == o], y[self.ori[rows] == o])
            for o in ORIENTATIONS
        }
        return self

    def predict(self, X: np.ndarray, rows: np.ndarray) -> np.ndarray:
        pred = np.empty(len(X), dtype=object)
        for o, model in self.models_.items():
            pred[self.ori[rows] == o] = model.predict(X[self.ori[rows] == o])
        return pred.astype(str)


def baselines(X: np.ndarray, y: np.ndarray, trials: Any) -> dict[str, Any]:
    """Per orientation and finger pad (24 electrodes): mean counts, stable - slipped,
    and the mean of each fifth of the file."""
    out: dict[str, Any] = {}
    pads = X[:, :72].reshape(len(X), 3, 24).mean(axis=2)
    order = trials["trial_id"].astype(str).to_numpy()
    for o in ORIENTATIONS:
        rows = np.flatnonzero(trials["orientation"].astype(str).to_numpy() == o)
        rows = rows[np.argsort(order[rows])]  # file order: <orientation>/<row>
        out[o] = {
            "mean": pads[rows].mean(axis=0).round(0).tolist(),
            "stable - slipped": (
                pads[rows][y[rows] == "stable"].mean(axis=0)
                - pads[rows][y[rows] == "slipped"].mean(axis=0)
            )
            .round(0)
            .tolist(),
            "fifths": [
                pads[part].mean(axis=0).round(0).tolist()
                for part in np.array_split(rows, 5)
            ],
        }
    return out


def run(seeds: int, finger: float, electrode: float) -> dict[str, Any]:
    """{condition: {candidate: {orientation: [score per seed]}}}."""
    root = Path(os.environ.get("SLIPKIT_DATA", "../shared/data")) / "bts3v2"
    ds = read_bts3v2(root)
    task = GraspStability()
    X, y, trials = task.arrays(ds)
    ori = trials["orientation"].astype(str).to_numpy()
    ids = trials["trial_id"].astype(str).to_numpy()
    n_e = X.shape[1] - len(ORIENTATIONS)
    res: dict[str, Any] = {
        "baselines": baselines(X, y, trials),
        "held out": {},
        "baseline shift": {},
        "orientation left out": {},
    }

    def add(cond: str, name: str, scores: dict[str, float]) -> None:
        row = res[cond].setdefault(name, {})
        for k, v in scores.items():
            row.setdefault(k, []).append(v)

    for seed in range(seeds):
        split = split_by_group(ds, "object", test_size=0.24, seed=seed)
        tr, te = np.isin(ids, split.train), np.isin(ids, split.test)
        rng = np.random.default_rng(seed)
        shifted = X[te].copy()
        for o in ORIENTATIONS:
            rows = ori[te] == o
            off = np.repeat(rng.normal(0.0, finger, 3), n_e // 3)
            shifted[rows, :n_e] += off + rng.normal(0.0, electrode, n_e)
        # (pipeline, input columns, orientation handling) per candidate
        cands: dict[str, tuple[Any, slice, str]] = {
            "plain logreg (raw, no orientation)": (
                make_pipeline(StandardScaler(), clone(FAMILIES["logreg"])),
                slice(0, n_e),
                "none",
            )
        }
        for fam, clf in FAMILIES.items():
            for mode in MODES:
                if (fam, mode) == ("logreg", "none"):
                    continue  # the plain logistic regression above
                pipe = grasp_pipeline(clf, n_electrodes=n_e)
                cands[f"{fam} {mode}"] = (
                    pipe.set_params(prep__normalise=mode),
                    slice(None),
                    mode,
                )
        for name, (pipe, cols, mode) in cands.items():
            fitted = clone(pipe).fit(X[tr][:, cols], y[tr])
            for cond, Xte in (("held out", X[te]), ("baseline shift", shifted)):
                add(cond, name, _scores(y[te], fitted.predict(Xte[:, cols]), ori[te]))
            if mode in BLIND:
                for o in ORIENTATIONS:
                    a, b = tr & (ori != o), te & (ori == o)
                    left = clone(pipe).fit(X[a][:, cols], y[a])
                    score = balanced_accuracy_score(y[b], left.predict(X[b][:, cols]))
                    add("orientation left out", name, {o: float(score)})
        for fam, clf in FAMILIES.items():
            pipe = grasp_pipeline(clf, n_electrodes=n_e)
            sep = PerOrientation(pipe.set_params(prep__normalise="shape"), ori)
            sep.fit(X[tr], y[tr], tr)
            name = f"{fam} shape, one per orientation"
            for cond, Xte in (("held out", X[te]), ("baseline shift", shifted)):
                add(cond, name, _scores(y[te], sep.predict(Xte, te), ori[te]))
    return res


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=5, help="held-out object sets")
    ap.add_argument("--finger", type=float, default=100.0, help="pad offset sd, counts")
    ap.add_argument(
        "--electrode", type=float, default=50.0, help="electrode offset sd, counts"
    )
    ap.add_argument("--json", action="store_true", help="print the JSON only")
    args = ap.parse_args()
    res = run(args.seeds, args.finger, args.electrode)
    if args.json:
        print(json.dumps(res, indent=1))
        return
    print("mean counts per finger pad (first, middle, thumb), all grasps:")
    for o, b in res.pop("baselines").items():
        print(f"  {o:<9} mean {b['mean']}  stable - slipped {b['stable - slipped']}")
        print(f"  {'':<9} fifths of the file {b['fifths']}")
    for cond, table in res.items():
        print(f"\n{cond} (balanced accuracy, mean +- sd over {args.seeds} seeds)")
        cols = ["all", *ORIENTATIONS, "worst"]
        print("| candidate | " + " | ".join(cols) + " |")
        print("|---" * (len(cols) + 1) + "|")
        for name, row in table.items():
            per = np.array([row[o] for o in ORIENTATIONS if o in row])
            row = {**row, "worst": list(per.min(axis=0))}
            cells = [
                f"{np.mean(row[c]):.3f} +- {np.std(row[c]):.3f}" if c in row else "-"
                for c in cols
            ]
            print(f"| {name} | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main()
