"""Sliding windows of frames: shapes, flattening order, modes and the NaN policy."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from slipkit.features.windows import (
    frames_for_ms,
    n_windows,
    sliding_windows,
    window_end_index,
)

FINITE = st.floats(-1e6, 1e6, allow_nan=False, width=64)


@st.composite
def trials(draw: st.DrawFn) -> np.ndarray:
    """A trial of 1-40 frames x 1-5 channels of finite values."""
    n = draw(st.integers(1, 40))
    c = draw(st.integers(1, 5))
    return draw(arrays(np.float64, (n, c), elements=FINITE))


@settings(max_examples=60, deadline=None)
@given(x=trials(), width=st.integers(1, 50), hop=st.integers(1, 7))
def test_window_count_and_end_frames_follow_the_formula(x, width, hop):
    """(n - W) // hop + 1 windows (0 if W > n), ending on frames W-1, W-1+hop, ..."""
    win = sliding_windows(x, width, hop=hop, dtype=np.float64)
    n, c = x.shape
    expected = max(0, (n - width) // hop + 1)
    assert expected == len(win.X) == len(win.end) == n_windows(n, width, hop)
    assert (expected, width * c) == win.X.shape
    assert list(range(width - 1, n, hop))[:expected] == win.end.tolist()
    assert win.end.tolist() == window_end_index(n, width, hop).tolist()


@settings(max_examples=60, deadline=None)
@given(x=trials(), width=st.integers(1, 40), hop=st.integers(1, 5))
def test_windows_are_the_frames_flattened_time_major(x, width, hop):
    """Window k reshaped to (W, C) is frames[end - W + 1 : end + 1], exactly."""
    win = sliding_windows(x, width, hop=hop, dtype=np.float64)
    for row, end in zip(win.X, win.end, strict=True):
        np.testing.assert_array_equal(
            x[end - width + 1 : end + 1], row.reshape(width, x.shape[1])
        )


@given(x=trials())
def test_width_one_gives_every_frame_and_full_width_gives_the_whole_trial(x):
    """W = 1: one window per frame (the frame itself); W = n: one window, the trial."""
    one = sliding_windows(x, 1, dtype=np.float64)
    np.testing.assert_array_equal(x, one.X)
    whole = sliding_windows(x, len(x), dtype=np.float64)
    np.testing.assert_array_equal(x.reshape(1, -1), whole.X)
    assert [len(x) - 1] == whole.end.tolist()


def test_a_window_longer_than_the_trial_gives_no_windows_of_the_right_shape():
    """W > n frames: empty arrays (0, W*C), not an error; a non-positive W is refused."""
    win = sliding_windows(np.ones((4, 3)), 5)
    assert (0, 15) == win.X.shape
    assert (0,) == win.end.shape
    empty = sliding_windows(np.empty((0, 3)), 2, mode="trial")
    assert (0, 6) == empty.X.shape
    with pytest.raises(ValueError, match="width"):
        sliding_windows(np.ones((4, 3)), 0)
    with pytest.raises(ValueError, match="hop"):
        sliding_windows(np.ones((4, 3)), 2, hop=0)
    with pytest.raises(ValueError, match="2-D"):
        sliding_windows(np.ones(4), 2)


@settings(max_examples=40, deadline=None)
@given(x=trials(), width=st.integers(1, 10))
def test_dynamics_modes_subtract_the_stated_reference(x, width):
    """'window' subtracts each window's first frame, 'trial' the trial's first frame."""
    raw = sliding_windows(x, width, dtype=np.float64).X.reshape(-1, width, x.shape[1])
    local = sliding_windows(x, width, mode="window", dtype=np.float64).X
    since = sliding_windows(x, width, mode="trial", dtype=np.float64).X
    np.testing.assert_allclose(
        raw - raw[:, :1], local.reshape(raw.shape), rtol=0, atol=0
    )
    np.testing.assert_allclose(raw - x[0], since.reshape(raw.shape), rtol=0, atol=0)


@settings(max_examples=40, deadline=None)
@given(x=trials(), width=st.integers(1, 10))
def test_first_frame_mode_repeats_the_origin_and_ignores_the_dynamics(x, width):
    """'first_frame': every window is frames[0] repeated W times, whatever follows."""
    win = sliding_windows(x, width, mode="first_frame", dtype=np.float64)
    expected = np.tile(x[0], (len(win.X), width))
    np.testing.assert_array_equal(expected, win.X)


def test_origin_replaces_the_first_frame_for_trial_and_first_frame_modes():
    """A given origin (the frame stored at contact) is what 'trial' subtracts."""
    x = np.arange(12.0).reshape(6, 2)
    origin = np.array([100.0, 200.0])
    win = sliding_windows(x, 2, mode="trial", origin=origin, dtype=np.float64)
    np.testing.assert_array_equal((x[:2] - origin).ravel(), win.X[0])
    with pytest.raises(ValueError, match="origin"):
        sliding_windows(x, 2, mode="trial", origin=[1.0, 2.0, 3.0])


def test_constant_signal_has_zero_dynamics():
    """A constant trial: both dynamics modes give all-zero windows."""
    x = np.full((20, 4), 2500.0)
    for mode in ("window", "trial"):
        assert 0.0 == float(np.abs(sliding_windows(x, 5, mode=mode).X).max())


def test_nan_frames_raise_are_omitted_or_propagate_as_asked():
    """A NaN in frame 5: 'raise' names it, 'omit' drops exactly the windows holding it."""
    x = np.arange(30.0).reshape(10, 3)
    x[5, 1] = np.nan
    with pytest.raises(ValueError, match="frame 5"):
        sliding_windows(x, 3)
    kept = sliding_windows(x, 3, nan_policy="omit")
    assert [2, 3, 4, 8, 9] == kept.end.tolist()
    assert np.isfinite(kept.X).all()
    kept = sliding_windows(x, 3, nan_policy="propagate")
    assert 8 == len(kept.X)
    assert 3 == int((~np.isfinite(kept.X).all(axis=1)).sum())


def test_output_dtype_is_float32_by_default():
    """The torch models take float32: that is the default dtype."""
    assert np.float32 == sliding_windows(np.ones((5, 2)), 2).X.dtype


@pytest.mark.parametrize(
    ("ms", "rate", "frames"),
    [(50, 100, 5), (100, 300, 30), (1, 100, 1), (333.4, 300, 100)],
)
def test_frames_for_ms_rounds_to_whole_frames_at_least_one(ms, rate, frames):
    """Window lengths in ms become whole frames at the stream's rate (>= 1)."""
    assert frames == frames_for_ms(ms, rate)


@settings(max_examples=50, deadline=None)
@given(
    x=trials(),
    width=st.integers(1, 8),
    bad=st.lists(st.integers(0, 39), max_size=4),
    value=st.sampled_from([np.nan, np.inf, -np.inf]),
)
def test_omit_keeps_exactly_the_windows_without_a_bad_frame(x, width, bad, value):
    """nan_policy='omit': a window is kept iff none of its W frames is non-finite."""
    bad = sorted({b for b in bad if b < len(x)})
    x = x.copy()
    x[bad, 0] = value
    kept = sliding_windows(x, width, nan_policy="omit", dtype=np.float64)
    expected = [
        end
        for end in window_end_index(len(x), width)
        if not any(end - width < b <= end for b in bad)
    ]
    assert expected == kept.end.tolist()


def test_module_imports_numpy_only_for_the_runtime():
    """windows.py imports nothing beyond numpy and the standard library's typing."""
    import ast

    import slipkit.features.windows as mod

    tree = ast.parse(Path(mod.__file__).read_text())
    roots = {
        (node.module if isinstance(node, ast.ImportFrom) else alias.name).split(".")[0]
        for node in ast.walk(tree)
        if isinstance(node, (ast.Import, ast.ImportFrom))
        for alias in node.names
    }
    assert {"__future__", "numpy", "typing"} == roots
