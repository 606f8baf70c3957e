"""Grasp stability from one tactile snapshot (BTS3v2, Garcia-Garcia et al. 2019).

biotacsp-stability-set-v2 holds one reading of three BioTac SPs (72 electrodes) per
grasp, taken before lifting, and whether the object then slipped. The hand grasped 41
objects in three palm orientations (down, side, 45 deg). :class:`GraspStability`
classifies stable vs slipped from that snapshot:

* **Split by object.** When the dataset holds the published test files (trials
  column ``published_split`` = ``test``: 10 objects recorded apart from the 41
  training ones), they are the test set and the training files the training side.
  Otherwise ``test_size`` of the objects (all their grasps, all orientations) are held
  out. Either way no grasp of a test object is ever seen in training.
* **Selection on the training objects only.** Each candidate family (logistic
  regression, RBF SVM, MLP: scikit-learn) gets an Optuna TPE search of its
  hyper-parameters and of the orientation handling (:class:`GraspFeatures`), scored by
  ``GroupKFold`` by object over the training objects. With
  ``scoring: worst_orientation_balanced_accuracy`` a candidate's score is, per fold,
  the balanced accuracy of its worst palm orientation (averaged over the folds), so a
  model that fails one orientation is not chosen. The family with the best
  validation score is refitted on all training objects; the test objects are scored
  once, after. The run's objective is that validation score.
* **Report.** Accuracy, balanced accuracy, per-class recall, overall and per palm
  orientation, for the chosen model and three controls fitted on the training objects:
  the majority class, the orientation alone (each orientation's majority class) and a
  plain standardised logistic regression on the raw electrodes.

The palm orientation shifts the electrode baseline (gravity loads the finger pads
differently), so :class:`GraspFeatures` offers five ways to cope, searched like any
hyper-parameter: ``none`` (raw electrodes), ``per_grasp`` (each finger's mean over
its 24 electrodes subtracted, i.e. the common offset of a pad removed), ``shape``
(``per_grasp``, then divided by that finger's spread over its 24 electrodes: the
pressure pattern of a pad, blind to its offset and gain), ``orientation_feature`` (a
one-hot orientation beside the electrodes) and ``per_orientation`` (electrodes
standardised with their orientation's training mean and standard deviation).
"""

from __future__ import annotations

import logging
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from sklearn.base import BaseEstimator, TransformerMixin, clone
from sklearn.linear_model import LogisticRegression
from sklearn.metrics import balanced_accuracy_score, get_scorer_names
from sklearn.model_selection import GroupKFold, cross_validate
from sklearn.pipeline import Pipeline
from sklearn.preprocessing import StandardScaler
from sklearn.utils.validation import check_is_fitted, validate_data

from slipkit.data.dataset import Dataset
from slipkit.data.splits import split_by_group
from slipkit.errors import SlipkitError
from slipkit.evaluate.metrics import classification_metrics
from slipkit.train.search import format_best, optuna_search, selection_record
from slipkit.train.task import Task, TaskResult

log = logging.getLogger("slipkit.grasp")

#: Orientation handling of :class:`GraspFeatures`.
NORMALISE = ("none", "per_grasp", "shape", "orientation_feature", "per_orientation")
#: Test sets of :class:`GraspStability` (``split``).
SPLITS = ("auto", "published", "objects")
#: Selection scoring of :class:`GraspStability`: the worst orientation's balanced accuracy.
WORST_ORIENTATION = "worst_orientation_balanced_accuracy"
#: Added to a pad's variance (counts^2) in ``shape``: a pad whose 24 electrodes read
#: alike stays finite (its pattern becomes 0); electrode counts are integers, so a
#: spread of 1 count is below anything a contact makes.
SHAPE_EPS = 1.0


class GraspFeatures(TransformerMixin, BaseEstimator):
    """Electrodes + one-hot orientation -> model features, one orientation handling.

    Input columns: ``n_electrodes`` electrode values (counts), then one 0/1 column per
    orientation (the task appends them). With ``E`` the electrodes and ``O`` the one-hot
    columns, every mode is one formula, ``Z = (E @ W - O @ M) / (O @ S)``, plus ``O``
    appended for ``orientation_feature``; ``shape`` then divides by each pad's spread,
    ``Z / sqrt((Z * Z) @ P + eps)``. Its ONNX graph is a handful of MatMul / Sub / Div
    (/ Mul / Sqrt) nodes.

    Parameters
    ----------
    normalise : {"none", "per_grasp", "shape", "orientation_feature", "per_orientation"}
        See the module docstring.
    n_electrodes : int
        Electrode columns (BTS3v2: 72, three fingers of 24).
    n_fingers : int
        Sensors whose electrodes are consecutive blocks (for ``per_grasp``, ``shape``).

    Attributes
    ----------
    W_ : ndarray of shape (n_electrodes, n_electrodes)
        Linear map of the electrodes (identity, or per-finger mean removal).
    M_, S_ : ndarray of shape (n_orientations, n_electrodes)
        Per-orientation offset and scale (0 and 1 except for ``per_orientation``).
    P_ : ndarray of shape (n_electrodes, n_electrodes) or None
        ``shape``: the per-finger averaging matrix (a pad's mean square, per electrode).
    """

    def __init__(
        self, *, normalise: str = "none", n_electrodes: int = 72, n_fingers: int = 3
    ) -> None:
        self.normalise = normalise
        self.n_electrodes = n_electrodes
        self.n_fingers = n_fingers

    def fit(self, X: Any, y: Any = None) -> GraspFeatures:
        """Learn the per-orientation mean / std (``per_orientation``) from ``X``."""
        X = validate_data(self, X, reset=True)
        if self.normalise not in NORMALISE:
            raise ValueError(
                f"normalise must be one of {list(NORMALISE)}; got {self.normalise!r}"
            )
        n_e = int(self.n_electrodes)
        if X.shape[1] <= n_e:
            raise ValueError(
                f"expected {n_e} electrode columns then one-hot orientations; got "
                f"{X.shape[1]} columns"
            )
        E, onehot = X[:, :n_e], X[:, n_e:]
        n_o = onehot.shape[1]
        self.W_ = np.eye(n_e)
        self.M_ = np.zeros((n_o, n_e))
        self.S_ = np.ones((n_o, n_e))
        self.P_: np.ndarray | None = None
        if self.normalise in ("per_grasp", "shape"):
            size = n_e // int(self.n_fingers)
            block = np.kron(
                np.eye(int(self.n_fingers)), np.full((size, size), 1 / size)
            )
            self.W_ = np.eye(n_e) - block
            if self.normalise == "shape":
                self.P_ = block
        elif self.normalise == "per_orientation":
            for k in range(n_o):
                rows = onehot[:, k] > 0.5
                if rows.any():
                    self.M_[k] = E[rows].mean(axis=0)
                    self.S_[k] = E[rows].std(axis=0)
            self.S_[self.S_ == 0] = 1.0  # a constant electrode: leave its scale
        return self

    def transform(self, X: Any) -> np.ndarray:
        """``(E @ W - O @ M) / (O @ S)``, then ``O`` for ``orientation_feature``."""
        check_is_fitted(self, "W_")
        # reset=False: keep n_features_in_ from fit, only check the shape.
        X = validate_data(self, X, reset=False)
        n_e = int(self.n_electrodes)
        E, onehot = X[:, :n_e], X[:, n_e:]
        # A row without an orientation keeps offset 0 and scale 1.
        scale = onehot @ self.S_ + (1.0 - onehot.sum(axis=1, keepdims=True))
        Z = (E @ self.W_ - onehot @ self.M_) / scale
        if self.P_ is not None:
            Z = Z / np.sqrt((Z * Z) @ self.P_ + SHAPE_EPS)
        if self.normalise == "orientation_feature":
            Z = np.hstack([Z, onehot])
        return np.asarray(Z)


def _onnx_shape(operator: Any) -> None:
    """skl2onnx shape calculator: (batch, n_electrodes [+ n_orientations])."""
    from skl2onnx.common.data_types import FloatTensorType

    op = operator.raw_operator
    width = int(op.n_electrodes)
    if op.normalise == "orientation_feature":
        width += int(op.M_.shape[0])
    operator.outputs[0].type = FloatTensorType([None, width])


def _onnx_convert(scope: Any, operator: Any, container: Any) -> None:
    """skl2onnx converter: ``(E @ W - O @ M) / (O @ S + 1 - sum(O))`` [, O]
    (``shape``: divided by ``sqrt((Z * Z) @ P + eps)``)."""
    from onnx import TensorProto

    op = operator.raw_operator
    n_e, n_o = int(op.n_electrodes), int(op.M_.shape[0])
    x = operator.inputs[0].full_name

    def name(stem: str) -> str:
        return str(scope.get_unique_variable_name(stem))

    def const(stem: str, value: np.ndarray, dtype: int = TensorProto.FLOAT) -> str:
        key = name(stem)
        arr = np.asarray(value)
        container.add_initializer(key, dtype, list(arr.shape), arr.ravel().tolist())
        return key

    def node(kind: str, inputs: list[str], stem: str, **attrs: Any) -> str:
        out = name(stem)
        container.add_node(
            kind, inputs, [out], name=scope.get_unique_operator_name(kind), **attrs
        )
        return out

    i64 = TensorProto.INT64
    axis = const("axis1", np.array([1]), i64)
    e = node(
        "Slice",
        [x, const("s0", np.array([0]), i64), const("e0", np.array([n_e]), i64), axis],
        "E",
    )
    o = node(
        "Slice",
        [
            x,
            const("s1", np.array([n_e]), i64),
            const("e1", np.array([n_e + n_o]), i64),
            axis,
        ],
        "O",
    )
    num = node(
        "Sub",
        [
            node("MatMul", [e, const("W", op.W_.astype(np.float32))], "EW"),
            node("MatMul", [o, const("M", op.M_.astype(np.float32))], "OM"),
        ],
        "num",
    )
    rest = node(
        "Sub",
        [
            const("one", np.array([1.0], dtype=np.float32)),
            node("ReduceSum", [o, axis], "osum", keepdims=1),
        ],
        "rest",
    )
    scale = node(
        "Add",
        [node("MatMul", [o, const("S", op.S_.astype(np.float32))], "OS"), rest],
        "scale",
    )
    z = node("Div", [num, scale], "Z")
    if op.P_ is not None:  # shape: Z / sqrt((Z * Z) @ P + eps)
        spread = node(
            "Sqrt",
            [
                node(
                    "Add",
                    [
                        node(
                            "MatMul",
                            [
                                node("Mul", [z, z], "Z2"),
                                const("P", op.P_.astype(np.float32)),
                            ],
                            "Z2P",
                        ),
                        const("eps", np.array([SHAPE_EPS], dtype=np.float32)),
                    ],
                    "var",
                )
            ],
            "spread",
        )
        z = node("Div", [z, spread], "Zs")
    out = operator.outputs[0].full_name
    if op.normalise == "orientation_feature":
        container.add_node(
            "Concat",
            [z, o],
            [out],
            name=scope.get_unique_operator_name("Concat"),
            axis=1,
        )
    else:
        container.add_node(
            "Identity", [z], [out], name=scope.get_unique_operator_name("Identity")
        )


def _register_onnx() -> None:
    """Teach skl2onnx :class:`GraspFeatures`, so a grasp Pipeline exports through
    :func:`slipkit.export.sklearn.export_sklearn` (skl2onnx has no converter for a
    custom transformer; this one is six MatMul / Sub / Div nodes)."""
    try:
        from skl2onnx import update_registered_converter
    except ImportError:  # a training install without skl2onnx: no export
        return
    update_registered_converter(
        GraspFeatures, "SlipkitGraspFeatures", _onnx_shape, _onnx_convert
    )


_register_onnx()


def grasp_pipeline(classifier: Any, *, n_electrodes: int = 72) -> Pipeline:
    """``GraspFeatures -> StandardScaler -> classifier`` (parameters ``prep__*``, ``clf__*``)."""
    return Pipeline(
        [
            ("prep", GraspFeatures(n_electrodes=n_electrodes)),
            ("scale", StandardScaler()),
            ("clf", clone(classifier)),
        ]
    )


class OrientationScorer:
    """Scikit-learn scorer ``(estimator, X, y) -> float`` on the grasp task's ``X``
    (electrodes, then one 0/1 column per orientation): the balanced accuracy of one
    orientation's rows (``column``), or of the worst orientation (``column=None``).

    The orientation is read from ``X`` itself, so the scorer works inside
    ``cross_val_score`` / ``cross_validate`` folds without a side channel.
    """

    def __init__(self, n_electrodes: int, column: int | None = None) -> None:
        self.n_electrodes = n_electrodes
        self.column = column

    def __call__(self, estimator: Any, X: np.ndarray, y: np.ndarray) -> float:
        onehot = np.asarray(X)[:, int(self.n_electrodes) :] > 0.5
        pred = np.asarray(estimator.predict(X))
        columns = range(onehot.shape[1]) if self.column is None else [self.column]
        scores = [
            float(balanced_accuracy_score(y[onehot[:, k]], pred[onehot[:, k]]))
            for k in columns
            if onehot[:, k].any()
        ]
        return min(scores) if scores else float("nan")


def _pipeline_space(space: Mapping[str, Any]) -> dict[str, Any]:
    """``normalise`` -> ``prep__normalise``; every other name -> ``clf__<name>``."""
    return {
        ("prep__normalise" if k == "normalise" else f"clf__{k}"): v
        for k, v in space.items()
    }


def _plain(params: Mapping[str, Any]) -> dict[str, Any]:
    return {k.split("__", 1)[-1]: v for k, v in params.items()}


class GraspStability(Task):
    """Stable vs slipped from one snapshot per grasp, split by object.

    Parameters
    ----------
    stream : str
        Snapshot stream (one row per trial, ``t = 0``).
    label : str
        Trial class label.
    classes : sequence of str
        The two classes, negative first (``stable``, ``slipped``).
    group : str
        Trials column whose values never straddle train / test or CV folds.
    orientation : str or None
        Trials column of the palm orientation (one-hot columns for
        :class:`GraspFeatures`, per-orientation scores); None: no orientation.
    orientations : sequence of str
        Its values, in column order (a dataset missing one still works).
    test_size : float
        Fraction of the objects held out (all their grasps) when the test set is
        drawn from the training objects.
    split : {"auto", "published", "objects"}
        The test set: the trials whose ``split_column`` reads ``test`` (the published
        test files; the rest train), ``test_size`` of the objects (``objects``; a
        dataset holding both sets leaves its test trials out), or the first when the
        dataset holds both sets (``auto``).
    split_column : str
        Trials column naming each grasp's published set (``train`` / ``test``).
    cv : int
        Folds of the group CV by object on the training side.
    scoring : str
        Selection scorer: a scikit-learn scorer name, or
        ``worst_orientation_balanced_accuracy`` (per fold, the balanced accuracy of
        the worst palm orientation). Objective ``validation.<scoring>``.
    n_trials : int
        Optuna candidates per model family.
    model_name : str
        Name of the run's ``model`` among the candidates.
    candidates : mapping, optional
        Further families, ``{name: estimator or _target_ node}``.
    spaces : mapping
        ``{family name: {param: spec}}`` (:mod:`slipkit.train.search` specs);
        ``normalise`` is the :class:`GraspFeatures` mode, any other name a parameter
        of the classifier. A family without an entry is scored as configured.
    """

    objective = "validation.balanced_accuracy"
    direction = "maximize"

    def __init__(
        self,
        *,
        stream: str = "electrodes",
        label: str = "slip_class",
        classes: Sequence[str] = ("stable", "slipped"),
        group: str = "object",
        orientation: str | None = "orientation",
        orientations: Sequence[str] = ("palm_down", "palm_side", "palm_45"),
        test_size: float = 0.2,
        split: str = "auto",
        split_column: str = "published_split",
        cv: int = 4,
        scoring: str = "balanced_accuracy",
        n_trials: int = 8,
        model_name: str = "model",
        candidates: Mapping[str, Any] | None = None,
        spaces: Mapping[str, Mapping[str, Any]] | None = None,
    ) -> None:
        self.stream = stream
        self.label = label
        self.classes = classes
        self.group = group
        self.orientation = orientation
        self.orientations = orientations
        self.test_size = test_size
        self.split = split
        self.split_column = split_column
        self.cv = cv
        self.scoring = scoring
        self.n_trials = n_trials
        self.model_name = model_name
        self.candidates = candidates
        self.spaces = spaces
        self.objective = f"validation.{scoring}"

    def _scorer(self, n_e: int) -> OrientationScorer | None:
        """The callable behind ``scoring`` (None: a scikit-learn scorer name)."""
        if str(self.scoring) == WORST_ORIENTATION:
            return OrientationScorer(n_e)
        if str(self.scoring) not in get_scorer_names():
            raise SlipkitError(
                f"task.scoring: unknown scorer {self.scoring!r}; use "
                f"{WORST_ORIENTATION!r} or a scikit-learn scorer name "
                "(balanced_accuracy, accuracy, f1_macro, ...)"
            )
        return None

    # -- data -------------------------------------------------------------------------
    def arrays(self, dataset: Dataset) -> tuple[np.ndarray, np.ndarray, pd.DataFrame]:
        """(X: electrodes then one-hot orientation, y: class names, trials table)."""
        if self.stream not in dataset.tables:
            raise SlipkitError(
                f"dataset {dataset.name or dataset.sensor!r} has no stream "
                f"{self.stream!r}; streams: {sorted(dataset.tables)}"
            )
        for col in (self.label, self.group, self.orientation):
            if col is not None and col not in dataset.trials.columns:
                raise SlipkitError(
                    f"dataset {dataset.name or dataset.sensor!r}: no trials column "
                    f"{col!r} (task.label / task.group / task.orientation); columns: "
                    f"{sorted(dataset.trials.columns)}"
                )
        table = dataset.tables[self.stream]
        channels = list(dataset.streams[self.stream].channels)
        first = table.drop_duplicates("trial_id").set_index("trial_id")
        if len(first) != len(table):
            raise SlipkitError(
                f"stream {self.stream!r}: {len(table)} rows for {len(first)} trials; "
                "grasp stability needs one snapshot per trial"
            )
        trials = dataset.trials.reset_index(drop=True)
        E = first.loc[trials["trial_id"], channels].to_numpy(dtype=np.float64)
        if self.orientation is None:
            onehot = np.ones((len(trials), 1))
        else:
            values = trials[self.orientation].astype(str).to_numpy()
            unknown = sorted(set(values) - set(map(str, self.orientations)))
            if unknown:
                raise SlipkitError(
                    f"trials column {self.orientation!r}: values {unknown} not in "
                    f"task.orientations {list(self.orientations)}"
                )
            onehot = (
                values[:, None] == np.asarray(self.orientations, dtype=str)
            ).astype(np.float64)
        y = trials[self.label].astype(str).to_numpy()
        bad = sorted(set(y) - set(map(str, self.classes)))
        if bad:
            raise SlipkitError(
                f"label {self.label!r}: classes {bad} not in task.classes "
                f"{list(self.classes)}"
            )
        return np.hstack([E, onehot]), y, trials

    def _families(self, model: Any) -> dict[str, Any]:
        from hydra.utils import instantiate

        fams = {str(self.model_name): model}
        for name, node in (self.candidates or {}).items():
            fams[str(name)] = clone(node) if hasattr(node, "fit") else instantiate(node)
        return fams

    def _baselines(self, X: np.ndarray, n_e: int) -> dict[str, Any]:
        """Mean electrode value (counts) per orientation and sensor of 24 electrodes:
        how far the orientation alone shifts the readings."""
        if self.orientation is None:
            return {}
        out: dict[str, Any] = {}
        size = n_e // 3
        for k, name in enumerate(self.orientations):
            rows = X[:, n_e + k] > 0.5
            if rows.any():
                E = X[rows, :n_e]
                out[str(name)] = {
                    f"sensor{j + 1}": float(E[:, j * size : (j + 1) * size].mean())
                    for j in range(3)
                }
        return out

    # -- scoring ----------------------------------------------------------------------
    def score(
        self, model: Any, X: np.ndarray, y: np.ndarray, trials: pd.DataFrame
    ) -> dict[str, Any]:
        """Classification metrics overall and per orientation."""
        return self._scores(np.asarray(model.predict(X)).astype(str), y, trials)

    def _scores(
        self, pred: np.ndarray, y: np.ndarray, trials: pd.DataFrame
    ) -> dict[str, Any]:
        """Metrics of ``pred`` overall, per orientation and of the worst orientation."""
        labels = [str(c) for c in self.classes]
        out = classification_metrics(y, pred, labels)
        if self.orientation is not None:
            ori = trials[self.orientation].astype(str).to_numpy()
            per = {
                str(o): classification_metrics(y[ori == o], pred[ori == o], labels)
                for o in self.orientations
                if (ori == o).any()
            }
            out["per_orientation"] = per
            out[WORST_ORIENTATION] = min(m["balanced_accuracy"] for m in per.values())
        else:
            out[WORST_ORIENTATION] = out["balanced_accuracy"]
        return out

    def _controls(
        self,
        X: np.ndarray,
        y: np.ndarray,
        tr: np.ndarray,
        te: np.ndarray,
        trials: pd.DataFrame,
        n_e: int,
    ) -> dict[str, Any]:
        """Controls fitted on the training grasps, scored on the test grasps: the
        majority class, the orientation alone (each orientation's training majority)
        and a plain standardised logistic regression on the raw electrodes."""
        t_trials = trials[te].reset_index(drop=True)
        vals, counts = np.unique(y[tr], return_counts=True)
        majority = str(vals[np.argmax(counts)])
        by_orientation = np.full(int(te.sum()), majority, dtype=object)
        onehot_tr, onehot_te = X[tr, n_e:] > 0.5, X[te, n_e:] > 0.5
        for k in range(onehot_tr.shape[1]):
            if onehot_tr[:, k].any():
                v, c = np.unique(y[tr][onehot_tr[:, k]], return_counts=True)
                by_orientation[onehot_te[:, k]] = str(v[np.argmax(c)])
        plain = Pipeline(
            [
                ("scale", StandardScaler()),
                ("clf", LogisticRegression(max_iter=5000)),
            ]
        ).fit(X[tr, :n_e], y[tr])
        return {
            "majority": {
                "class": majority,
                **self._scores(np.full(int(te.sum()), majority), y[te], t_trials),
            },
            "orientation_only": self._scores(
                by_orientation.astype(str), y[te], t_trials
            ),
            "plain_logreg": self._scores(
                np.asarray(plain.predict(X[te, :n_e])).astype(str), y[te], t_trials
            ),
        }

    def _validation_table(
        self, pipe: Pipeline, X: np.ndarray, y: np.ndarray, groups: np.ndarray, n_e: int
    ) -> dict[str, Any]:
        """``pipe`` scored by the same group CV (training objects only): the selection
        scoring, balanced accuracy, and balanced accuracy per orientation."""
        scoring: dict[str, Any] = {
            "selection": self._scorer(n_e) or str(self.scoring),
            "balanced_accuracy": "balanced_accuracy",
        }
        names = [str(o) for o in self.orientations] if self.orientation else []
        for k, o in enumerate(names):
            scoring[f"orientation {o}"] = OrientationScorer(n_e, k)
        res = cross_validate(
            pipe, X, y, groups=groups, cv=GroupKFold(int(self.cv)), scoring=scoring
        )
        sel = np.asarray(res["test_selection"], dtype=float)
        return {
            str(self.scoring): float(np.mean(sel)),
            "std": float(np.std(sel)),
            "folds": [float(v) for v in sel],
            "balanced_accuracy": float(np.mean(res["test_balanced_accuracy"])),
            "per_orientation": {
                o: float(np.nanmean(res[f"test_orientation {o}"])) for o in names
            },
        }

    def _majority(
        self, cls: str, y: np.ndarray, trials: pd.DataFrame
    ) -> dict[str, Any]:
        """Always answering ``cls`` (the training side's most frequent class)."""
        const = np.full(len(y), cls)
        labels = [str(c) for c in self.classes]
        out = {"class": cls, **classification_metrics(y, const, labels)}
        if self.orientation is not None:
            ori = trials[self.orientation].astype(str).to_numpy()
            out["per_orientation"] = {
                str(o): float(np.mean(y[ori == o] == cls))
                for o in self.orientations
                if (ori == o).any()
            }
        return out

    # -- fit --------------------------------------------------------------------------
    def _split(
        self, dataset: Dataset, trials: pd.DataFrame, seed: int
    ) -> tuple[np.ndarray, np.ndarray, str]:
        """(train mask, test mask, what the test set is) over ``trials``."""
        if self.split not in SPLITS:
            raise SlipkitError(
                f"task.split: {self.split!r}; expected one of {list(SPLITS)}"
            )
        col = str(self.split_column)
        published = (
            trials[col].astype(str).to_numpy() == "test"
            if col in trials.columns
            else np.zeros(len(trials), dtype=bool)
        )
        # Both sets present: the published split is there to use (a dataset of one
        # set alone is split by object like any other).
        both = bool(published.any() and not published.all())
        if self.split == "published" and not both:
            raise SlipkitError(
                f"task.split=published: {dataset.name!r} needs trials with {col} = "
                "'train' and 'test'; import the published test files (bts3v2_"
                "<orientation>_test.csv) beside the training files, or set "
                "task.split=objects"
            )
        groups = trials[self.group].astype(str).to_numpy()
        if self.split != "objects" and both:
            shared = sorted(set(groups[published]) & set(groups[~published]))
            if shared:
                raise SlipkitError(
                    f"{dataset.name!r}: objects {shared} are in both the published "
                    f"training and test files ({col}); the test objects must be unseen"
                )
            return ~published, published, "published test files"
        ids = trials["trial_id"].astype(str).to_numpy()
        own = dataset.subset(list(ids[~published])) if both else dataset
        try:
            split = split_by_group(
                own, self.group, test_size=float(self.test_size), seed=seed
            )
        except (ValueError, KeyError) as exc:
            raise SlipkitError(f"cannot split {dataset.name!r}: {exc}") from None
        return np.isin(ids, split.train), np.isin(ids, split.test), "held-out objects"

    def fit(self, model: Any, dataset: Dataset, *, seed: int, out: Path) -> TaskResult:
        X, y, trials = self.arrays(dataset)
        tr, te, kind = self._split(dataset, trials, seed)
        groups = trials[self.group].astype(str).to_numpy()
        n_e = X.shape[1] - (1 if self.orientation is None else len(self.orientations))
        log.info(
            "grasps: %d train (%d objects), %d test (%d objects)",
            tr.sum(),
            len(set(groups[tr])),
            te.sum(),
            len(set(groups[te])),
        )
        scorer = self._scorer(n_e)
        # Selection: training objects only; the test objects are not touched here.
        records: dict[str, dict[str, Any]] = {}
        pipelines: dict[str, Pipeline] = {}
        spaces = dict(self.spaces or {})
        for name, clf in self._families(model).items():
            pipe = grasp_pipeline(clf, n_electrodes=n_e)
            space = _pipeline_space(spaces.get(name) or {})
            if not space:  # nothing to search: one candidate, the configured one
                space = {"prep__normalise": {"choices": ["none"]}}
            best, score, history = optuna_search(
                pipe,
                X[tr],
                y[tr],
                groups[tr],
                space=space,
                n_trials=int(self.n_trials) if spaces.get(name) else 1,
                cv=int(self.cv),
                scoring=str(self.scoring),
                seed=seed,
                unit="object",
                label=f"grasp {name} ({type(clf).__name__}) search",
                scorer=scorer,
            )
            records[name] = selection_record(
                _plain(best),
                score,
                [{**h, **_plain({k: h[k] for k in space})} for h in history],
                cv=int(self.cv),
                scoring=str(self.scoring),
                unit="object",
            )
            for c in records[name]["candidates"]:
                c["params"] = {k: v for k, v in c["params"].items() if "__" not in k}
            pipelines[name] = pipe.set_params(**best)
        chosen = max(records, key=lambda n: records[n]["best_score"])
        selection = {
            **{k: v for k, v in records[chosen].items() if k != "candidates"},
            "best": {"model": chosen, **records[chosen]["best"]},
            "candidates": [
                {**c, "params": {"model": name, **c["params"]}}
                for name, rec in records.items()
                for c in rec["candidates"]
            ],
            "by_model": {
                n: {"best": r["best"], "best_score": r["best_score"]}
                for n, r in records.items()
            },
        }
        log.info("%s", format_best(selection))
        # Which orientation handling helps, measured on validation: the chosen model
        # and hyper-parameters with each mode, same group CV (training objects only).
        at_best = {
            mode: self._validation_table(
                clone(pipelines[chosen]).set_params(prep__normalise=mode),
                X[tr],
                y[tr],
                groups[tr],
                n_e,
            )
            for mode in NORMALISE
        }
        final = pipelines[chosen].fit(X[tr], y[tr])
        best_row = max(records[chosen]["candidates"], key=lambda c: c["mean"])
        validation = {
            "cv": f"group-kfold by {self.group}",
            "k": int(self.cv),
            "scoring": str(self.scoring),
            str(self.scoring): records[chosen]["best_score"],
            "std": best_row["std"],
            "source": "selection (best candidate of the chosen model)",
            # The chosen candidate re-scored by the same folds, per orientation.
            **{
                k: at_best[str(pipelines[chosen].get_params()["prep__normalise"])][k]
                for k in ("balanced_accuracy", "per_orientation")
            },
        }
        # The test objects, scored once with the chosen model.
        vals, counts = np.unique(y[tr], return_counts=True)
        majority_cls = str(vals[np.argmax(counts)])
        t_trials = trials[te].reset_index(drop=True)
        metrics: dict[str, Any] = {
            "model": chosen,
            "params": {"model": chosen, **records[chosen]["best"]},
            "split": {
                "by": self.group,
                "test_set": kind,
                "train_objects": sorted(set(groups[tr])),
                "test_objects": sorted(set(groups[te])),
                "n_train": int(tr.sum()),
                "n_test": int(te.sum()),
            },
            "selection": selection,
            "validation": validation,
            "orientation_baseline_counts": self._baselines(X[tr], n_e),
            "normalisation": _normalisation_table(records),
            "normalisation_at_best": at_best,
            "train": self.score(final, X[tr], y[tr], trials[tr].reset_index(drop=True)),
            "test": self.score(final, X[te], y[te], t_trials),
            "majority_control_test": self._majority(majority_cls, y[te], t_trials),
            "controls_test": self._controls(X, y, tr, te, trials, n_e),
        }
        _write_tables(metrics, out)
        return TaskResult(final, metrics, _summary(metrics))

    def evaluate(self, model: Any, dataset: Dataset, *, out: Path) -> dict[str, Any]:
        """Scores over the grasps of ``dataset`` as ``test`` (overall, per
        orientation): every grasp, or only the published test files' when the dataset
        holds both sets."""
        X, y, trials = self.arrays(dataset)
        col = str(self.split_column)
        held_out = False
        if col in trials.columns:
            published = trials[col].astype(str).to_numpy() == "test"
            if published.any() and not published.all():
                X, y = X[published], y[published]
                trials = trials[published].reset_index(drop=True)
                held_out = True  # fit never trains on these (see _split)
        pred = np.asarray(model.predict(X)).astype(str)
        pd.DataFrame({"trial_id": trials["trial_id"], "label": y, "pred": pred}).to_csv(
            out / "predictions.csv", index=False
        )
        return {"test": self.score(model, X, y, trials), "held_out_only": held_out}


def _normalisation_table(records: Mapping[str, Mapping[str, Any]]) -> dict[str, Any]:
    """Best validation score per (model, orientation handling) among the candidates."""
    table: dict[str, dict[str, float]] = {}
    for name, rec in records.items():
        for c in rec["candidates"]:
            mode = str(c["params"].get("normalise", "none"))
            row = table.setdefault(name, {})
            if c["mean"] is not None and c["mean"] > row.get(mode, -np.inf):
                row[mode] = float(c["mean"])
    return table


#: Rows of the per-orientation tables: (metrics key, label).
_ROWS = (
    ("test", "chosen model"),
    ("plain_logreg", "plain logistic regression"),
    ("orientation_only", "orientation only"),
    ("majority", "majority class"),
)


def _scored(metrics: Mapping[str, Any]) -> list[tuple[str, str, Mapping[str, Any]]]:
    """(key, label, metrics) of the chosen model and each control on the test objects."""
    controls = metrics["controls_test"]
    return [
        (key, label, metrics["test"] if key == "test" else controls[key])
        for key, label in _ROWS
    ]


def _write_tables(metrics: Mapping[str, Any], out: Path) -> None:
    rows = []
    for key, _, m in _scored(metrics):
        parts = [("all", m), *m.get("per_orientation", {}).items()]
        for o, mo in parts:
            rows.append(
                {
                    "scored": key,
                    "orientation": o,
                    "n": mo["n"],
                    "accuracy": mo["accuracy"],
                    "balanced_accuracy": mo["balanced_accuracy"],
                    **{f"recall_{k}": v for k, v in mo["recall"].items()},
                }
            )
    pd.DataFrame(rows).to_csv(out / "scores.csv", index=False)
    pd.DataFrame(metrics["normalisation"]).to_csv(out / "normalisation.csv")


def _summary(metrics: Mapping[str, Any]) -> list[str]:
    sp, te, maj = metrics["split"], metrics["test"], metrics["majority_control_test"]
    val = metrics["validation"]
    orientations = list(te.get("per_orientation", {}))
    lines = [
        f"Grasp stability, split by {sp['by']}: {len(sp['train_objects'])} train objects "
        f"({sp['n_train']} grasps) / {len(sp['test_objects'])} test objects "
        f"({sp['n_test']} grasps; {sp.get('test_set', 'held-out objects')})",
        "  " + format_best(metrics["selection"]),
        f"  validation ({val['cv']}, k={val['k']}): {val['scoring']} "
        f"{val[val['scoring']]:.4f} +- {val['std']:.4f}",
        f"  test objects: accuracy {te['accuracy']:.4f}, balanced "
        f"{te['balanced_accuracy']:.4f}, recall "
        + ", ".join(f"{k} {v:.3f}" for k, v in te["recall"].items()),
        f"  majority control (always {maj['class']!r}): accuracy {maj['accuracy']:.4f}, "
        f"balanced {maj['balanced_accuracy']:.4f}",
        "  accuracy / balanced accuracy    "
        + "".join(f"{o:>16}" for o in ["all", *orientations]),
    ]
    for _, label, m in _scored(metrics):
        cells = [m, *(m["per_orientation"][o] for o in orientations)]
        lines.append(
            f"    {label:<30}"
            + "".join(
                f"   {c['accuracy']:.3f} / {c['balanced_accuracy']:.3f}" for c in cells
            )
        )
    if orientations:
        lines.append(
            f"    {'validation (training objects)':<30}   {'- / ':>8}"
            f"{val['balanced_accuracy']:.3f}"
            + "".join(
                f"   {'- / ':>8}{val['per_orientation'][o]:.3f}" for o in orientations
            )
        )
    for o, b in metrics["orientation_baseline_counts"].items():
        lines.append(
            f"  mean electrode (counts, training grasps) {o:<10} "
            + ", ".join(f"{k} {v:.0f}" for k, v in b.items())
        )
    lines.append(
        f"  orientation handling with the chosen {metrics['model']} parameters "
        f"(validation {val['scoring']}):"
    )
    lines.append(
        "    "
        + ", ".join(
            f"{mode} {v[val['scoring']]:.4f}"
            for mode, v in metrics["normalisation_at_best"].items()
        )
    )
    lines.append(
        "  best validation per orientation handling among the searched candidates:"
    )
    for name, row in metrics["normalisation"].items():
        lines.append(
            f"    {name:<8} " + ", ".join(f"{k} {v:.4f}" for k, v in row.items())
        )
    return lines


__all__: Sequence[str] = [
    "NORMALISE",
    "SPLITS",
    "WORST_ORIENTATION",
    "GraspFeatures",
    "GraspStability",
    "OrientationScorer",
    "grasp_pipeline",
]
