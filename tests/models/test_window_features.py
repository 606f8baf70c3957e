"""WindowStatistics (per-electrode window statistics) and CandidateSearch (group-CV selection)."""

from __future__ import annotations

import numpy as np
import pytest
from sklearn.dummy import DummyClassifier
from sklearn.linear_model import LogisticRegression
from sklearn.pipeline import make_pipeline
from sklearn.preprocessing import StandardScaler
from sklearn.utils.estimator_checks import parametrize_with_checks

from slipkit.models.selection import CandidateSearch
from slipkit.models.window_features import STATS, WindowStatistics


@parametrize_with_checks(
    [WindowStatistics(n_channels=1)],
    # None known: the transformer passes every check with one channel.
    expected_failed_checks=lambda est: {},
)
def test_scikit_learn_transformer_contract(estimator, check):
    """WindowStatistics passes scikit-learn's estimator checks."""
    check(estimator)


def test_statistics_of_a_hand_made_window_are_stat_major():
    """Two channels over three frames: the six statistics, every channel, in order."""
    frames = np.array([[1.0, 10.0], [3.0, 10.0], [2.0, 16.0]])  # (W=3, C=2)
    out = WindowStatistics(n_channels=2).fit_transform(frames.reshape(1, -1))
    expected = [
        2.0, 12.0,  # mean
        np.sqrt(2.0 / 3.0), np.sqrt(8.0),  # std (population)
        1.0, 10.0,  # min
        3.0, 16.0,  # max
        1.0, 6.0,  # last - first
        1.5, 3.0,  # mean |diff|
    ]  # fmt: skip
    np.testing.assert_allclose([expected], out)
    names = WindowStatistics(n_channels=2).fit(frames.reshape(1, -1))
    assert "mean_abs_diff_c1" == names.get_feature_names_out()[-1]


def test_subtract_first_removes_the_level_and_keeps_the_changes():
    """A constant offset changes nothing with subtract_first; without it the means move."""
    rng = np.random.default_rng(0)
    X = rng.normal(0.0, 1.0, (5, 4 * 3))
    shifted = X + 2500.0
    rel = WindowStatistics(n_channels=3, subtract_first=True).fit(X)
    np.testing.assert_allclose(rel.transform(X), rel.transform(shifted), atol=1e-9)
    raw = WindowStatistics(n_channels=3).fit(X)
    assert not np.allclose(raw.transform(X), raw.transform(shifted))


def test_one_frame_window_has_no_change_and_bad_shapes_are_named():
    """W = 1: std, last-first and mean |diff| are 0; a width not a multiple of C is refused."""
    out = WindowStatistics(n_channels=2).fit_transform([[4.0, 5.0]])
    assert len(STATS) * 2 == out.shape[1]
    np.testing.assert_array_equal([[4.0, 5.0, 0, 0, 4, 5, 4, 5, 0, 0, 0, 0]], out)
    with pytest.raises(ValueError, match="n_channels=3"):
        WindowStatistics(n_channels=3).fit(np.zeros((2, 4)))
    with pytest.raises(ValueError, match="subset"):
        WindowStatistics(n_channels=2, stats=["median"]).fit(np.zeros((2, 4)))


def grouped_problem(seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Two classes separated by feature 0, in 5 groups (objects) of 40 rows."""
    rng = np.random.default_rng(seed)
    y = np.tile(["a", "b"], 100)
    X = rng.normal(0.0, 1.0, (200, 3))
    X[:, 0] += np.where(y == "b", 3.0, 0.0)
    return X, y, np.repeat(np.arange(5), 40)


def test_search_picks_the_better_candidate_by_leave_one_group_out():
    """A logistic regression beats the majority class; the record names it and every pair."""
    X, y, g = grouped_problem()
    search = CandidateSearch(
        candidates={
            "majority": DummyClassifier(),
            "lr": make_pipeline(StandardScaler(), LogisticRegression()),
        },
        grids={"lr": {"logisticregression__C": [0.01, 1.0]}},
        verbose=False,
    ).fit(X, y, groups=g)
    sel = search.selection_
    assert "lr" == search.best_name_
    assert ("leave-one-object-out", "balanced_accuracy") == (sel["cv"], sel["scoring"])
    assert [
        ("majority", {}),
        ("lr", {"logisticregression__C": 0.01}),
        ("lr", {"logisticregression__C": 1.0}),
    ] == [(c["name"], c["params"]) for c in sel["candidates"]]
    assert 5 == len(search.cv_results_[0]["scores"])
    assert 0.5 == sel["candidates"][0]["mean"]
    assert sel["best_score"] == max(c["mean"] for c in sel["candidates"])
    assert ["a", "b"] == search.classes_.tolist()
    np.testing.assert_array_equal(
        search.best_estimator_.predict_proba(X), search.predict_proba(X)
    )


def test_search_validation_never_holds_a_training_group():
    """Every inner fold validates on one whole group (leave-one-group-out on the groups given)."""
    X, y, g = grouped_problem()

    class Recorder(DummyClassifier):
        seen: list[set[int]] = []  # noqa: RUF012  (a test probe shared across clones)

        def fit(self, X, y, groups=None):
            Recorder.seen.append(set(np.unique(groups).tolist()))
            return super().fit(X, y)

    CandidateSearch(candidates={"r": Recorder()}, verbose=False).fit(X, y, groups=g)
    inner, refit = Recorder.seen[:-1], Recorder.seen[-1]
    assert [set(range(5)) - {k} for k in range(5)] == inner
    assert set(range(5)) == refit


def test_search_errors_name_the_problem():
    """One group, or a grid for an unknown candidate, is a clear ValueError."""
    X, y, g = grouped_problem()
    with pytest.raises(ValueError, match="needs >= 2 groups"):
        CandidateSearch(candidates={"d": DummyClassifier()}, verbose=False).fit(
            X, y, groups=np.zeros(len(y))
        )
    with pytest.raises(
        ValueError, match=r"grids name candidates that do not exist: \['x'\]"
    ):
        CandidateSearch(
            candidates={"d": DummyClassifier()}, grids={"x": {"C": [1]}}, verbose=False
        ).fit(X, y, groups=g)


def test_parallel_inner_folds_give_the_same_record():
    """n_jobs=2 scores the same folds as the serial loop: identical candidates and choice."""
    X, y, g = grouped_problem(seed=1)
    kw = {
        "candidates": {"majority": DummyClassifier(), "lr": LogisticRegression()},
        "verbose": False,
    }
    serial = CandidateSearch(**kw).fit(X, y, groups=g)
    parallel = CandidateSearch(**kw, n_jobs=2).fit(X, y, groups=g)
    assert serial.selection_ == parallel.selection_


def test_a_list_of_grids_tries_each_sub_grid():
    """grids may list sub-grids (ParameterGrid's list form): their pairs, in order."""
    X, y, g = grouped_problem()
    search = CandidateSearch(
        candidates={"lr": make_pipeline(StandardScaler(), LogisticRegression())},
        grids={
            "lr": [
                {"logisticregression__C": [0.1, 1.0]},
                {"logisticregression__C": [10.0], "standardscaler": ["passthrough"]},
            ]
        },
        verbose=False,
    ).fit(X, y, groups=g)
    assert [
        {"logisticregression__C": 0.1},
        {"logisticregression__C": 1.0},
        {"logisticregression__C": 10.0, "standardscaler": "passthrough"},
    ] == [c["params"] for c in search.selection_["candidates"]]
