"""TacTipSVM export: MatMul/Exp scores equal decision_function; in-graph pin-velocity features equal numpy."""

from __future__ import annotations

import functools

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st
from sklearn.datasets import make_classification

from slipkit.export import (
    ExportError,
    check_parity,
    export_velocity_features,
)
from slipkit.export.parity import onnx_session, run_graph
from slipkit.families.tactip.export.svm import export_tactip_svm
from slipkit.features.pins import circular_mean, velocity_features, wrap_angle
from slipkit.models import TacTipSVM

REL = 1e-4  # max |score difference| / max |score| (issue 6)


def _rel_diff(ours: np.ndarray, ref: np.ndarray) -> float:
    return float(np.max(np.abs(ours - ref)) / np.max(np.abs(ref)))


def _features_of(pins: np.ndarray, **kw) -> np.ndarray:
    """velocity_features of (n, 2, 2N) pin-frame pairs, float64 numpy."""
    p = pins.astype(np.float64)
    n = p.shape[-1] // 2
    with np.errstate(invalid="ignore"):  # inf - inf: a missing pin, as intended
        d = p[:, 1] - p[:, 0]
    return velocity_features(np.stack([d[:, :n], d[:, n:]], axis=-1), **kw)


def _circular(a: np.ndarray) -> np.ndarray:
    """Angle differences folded into [-pi, pi] (rad)."""
    return np.abs((a + np.pi) % (2 * np.pi) - np.pi)


@pytest.mark.parametrize("kernel", ["rbf", "linear"])
@pytest.mark.parametrize("standardize", [False, True])
def test_scores_equal_decision_function_on_held_out_frames(
    drop_data, kernel: str, standardize: bool
):
    """Graph scores match decision_function to 1e-4 relative; decisions and parity agree."""
    svm = TacTipSVM(kernel=kernel, standardize=standardize).fit(
        drop_data.X_train, drop_data.y_train
    )
    graph = export_tactip_svm(svm)
    ours = run_graph(graph, drop_data.X_test)
    ref = svm.decision_function(drop_data.X_test)
    assert _rel_diff(ours, ref) <= REL
    np.testing.assert_array_equal(
        svm.predict(drop_data.X_test), np.where(ours > 0, *reversed(svm.classes_))
    )
    report = check_parity(svm, graph, drop_data.X_test)
    assert (True, 1.0) == (report["passed"], report["agreement"])
    assert ("slip", "static") == graph.classes
    assert 0.0 == graph.threshold


def test_rbf_graph_uses_matrix_products_not_the_svm_operator(drop_data):
    """The RBF graph is built from Gemm/Exp over the support vectors, with no ai.onnx.ml node."""
    svm = TacTipSVM().fit(drop_data.X_train, drop_data.y_train)
    model = export_tactip_svm(svm).model
    ops = {n.op_type for n in model.graph.node}
    assert {"Gemm", "Exp"} <= ops
    assert {""} == {n.domain for n in model.graph.node}
    n_sv = svm.svc_.support_vectors_.shape[0]
    shapes = [tuple(t.dims) for t in model.graph.initializer]
    assert (drop_data.X_train.shape[1], n_sv) in shapes


@pytest.mark.parametrize("standardize", [False, True])
def test_linear_kernel_collapses_to_one_weight_vector(drop_data, standardize: bool):
    """A linear SVM exports one (F, 1) weight vector = coef_ / scale, not its support vectors."""
    svm = TacTipSVM(kernel="linear", standardize=standardize).fit(
        drop_data.X_train, drop_data.y_train
    )
    model = export_tactip_svm(svm).model
    n_features = drop_data.X_train.shape[1]
    from onnx import numpy_helper

    weights = [numpy_helper.to_array(t) for t in model.graph.initializer]
    assert n_features + 1 >= max(w.size for w in weights)
    (w,) = [w for w in weights if w.shape == (n_features, 1)]
    scale = svm.scaler_.scale_ if standardize else 1.0
    np.testing.assert_allclose(
        svm.svc_.coef_.ravel() / scale, w.ravel(), rtol=1e-6, atol=1e-7
    )
    assert "Exp" not in {n.op_type for n in model.graph.node}


@pytest.mark.parametrize("standardize", [False, True])
def test_graph_with_features_inside_takes_raw_pin_frames(drop_data, standardize: bool):
    """From raw (prev, cur) pin frames the graph reproduces features + decision_function; parity passes."""
    svm = TacTipSVM(standardize=standardize).fit(drop_data.X_train, drop_data.y_train)
    graph = export_tactip_svm(svm, with_features=True)
    assert ("batch", 2, 254) == graph.input_shape
    assert 127 == graph.features["n_pins"]
    pins = drop_data.pins_test
    assert np.isnan(pins).any()  # the scene drops pins: the NaN rule is exercised
    ref = svm.decision_function(_features_of(pins))
    ours = run_graph(graph, pins)
    assert _rel_diff(ours, ref) <= REL
    report = check_parity(svm, graph, pins)
    assert (True, 0) == (report["passed"], report["n_disagree"])


def test_float32_positions_keep_decisions_and_centred_positions_keep_features(
    drop_data,
):
    """Float32 absolute positions blur slow pins' angles yet keep decisions; centred ones match X closely."""
    svm = TacTipSVM().fit(drop_data.X_train, drop_data.y_train)
    graph = export_tactip_svm(svm, with_features=True)
    ref = svm.decision_function(drop_data.X_test)  # float64 features of float64 pins
    ours = run_graph(graph, drop_data.pins_test)  # float32 pins (~1e-6 mm resolution)
    assert 0.999 <= np.mean((ref > 0) == (ours > 0))
    # A constant offset cancels in the velocity: subtracting one reference frame in
    # float64 before the cast keeps the float32 resolution on the small numbers.
    p64 = drop_data.pins_test64
    centred = (p64 - p64[:1, :1]).astype(np.float32)
    out = run_graph(export_velocity_features(127), centred)
    X = drop_data.X_test
    np.testing.assert_allclose(X[:, :127], out[:, :127], rtol=1e-6, atol=1e-5)
    # Slowest pins move ~1e-4 mm/frame against ~1e-7 mm of float32 resolution at 1 mm.
    assert 1e-3 >= _circular(out[:, 127:] - X[:, 127:]).max()


def test_hand_worked_frame_with_antiparallel_still_and_missing_pins():
    """Velocities (1, 0), (-1, 0), (-1, -0), still, NaN: dr and angles at exactly +-pi as worked out."""
    nan = np.nan
    # Pins 0..4: x then y, previous frame and current frame (mm).
    prev = np.r_[[0.0, 1.0, 1.0, 5.0, nan], [2.0, 2.0, 0.0, 7.0, 1.0]]
    cur = np.r_[[1.0, 0.0, 0.0, 5.0, 3.0], [2.0, 2.0, -0.0, 7.0, 1.0]]
    pins = np.asarray([[prev, cur]], dtype=np.float32)
    # Unit velocities sum to (-1, 0): mean direction pi. Pin 0 points against it
    # (+pi after the wrap), pins 1 and 2 along it (0); pin 3 is still, pin 4 missing.
    shifted = np.r_[[1.0, 1.0, 1.0, 0.0, 0.0], [np.pi, 0.0, 0.0, 0.0, 0.0], 1.0]
    # Raw atan2 keeps the sign of a zero dy: (-1, +0) -> pi, (-1, -0) -> -pi.
    raw = np.r_[[1.0, 1.0, 1.0, 0.0, 0.0], [0.0, np.pi, -np.pi, 0.0, 0.0], 1.0]
    for shift, expected in ((True, shifted), (False, raw)):
        graph, session = _features_session(5, "dr_dtheta", shift, True)
        out = run_graph(graph, pins, session=session)[0]
        ref = _features_of(pins, shift_angles=shift, missing_count=True)[0]
        np.testing.assert_allclose(expected, ref, atol=1e-12)
        np.testing.assert_allclose(expected, out, atol=1e-6)


def test_nearly_cancelling_unit_vectors_have_no_mean_direction():
    """Velocities (1, 3) and (-7, -21) cancel to ~1e-16: mean 0 rad, angles stay unshifted."""
    pins = np.asarray([[[0, 0, 0, 0], [1, -7, 3, -21]]], dtype=np.float32)
    expected = np.r_[np.hypot(1, 3), np.hypot(7, 21), np.arctan2([3, -21], [1, -7])]
    graph, session = _features_session(2, "dr_dtheta", True, False)
    out = run_graph(graph, pins, session=session)[0]
    np.testing.assert_allclose(expected, _features_of(pins)[0], atol=1e-12)
    np.testing.assert_allclose(expected, out, rtol=1e-6, atol=1e-6)


@pytest.mark.parametrize(
    "level", ["ORT_DISABLE_ALL", "ORT_ENABLE_BASIC", "ORT_ENABLE_ALL"]
)
def test_hand_worked_frame_is_the_same_at_every_optimisation_level(level: str):
    """Signed zeros survive onnxruntime's graph rewrites: raw -pi stays -pi, shifted +pi stays +pi."""
    import onnxruntime as ort

    nan = np.nan
    prev = np.r_[[0.0, 1.0, 1.0, 5.0, nan, 0.0], [2.0, 2.0, 0.0, 7.0, 1.0, 0.0]]
    cur = np.r_[[1.0, 0.0, 0.0, 5.0, 3.0, 0.0], [2.0, 2.0, -0.0, 7.0, 1.0, 2.0]]
    pins = np.asarray([[prev, cur]], dtype=np.float32)
    options = ort.SessionOptions()
    options.graph_optimization_level = getattr(ort.GraphOptimizationLevel, level)
    for shift in (True, False):
        graph = export_velocity_features(6, shift_angles=shift, missing_count=True)
        session = ort.InferenceSession(
            graph.serialize(), options, providers=["CPUExecutionProvider"]
        )
        out = run_graph(graph, pins, session=session)[0]
        ref = _features_of(pins, shift_angles=shift, missing_count=True)[0]
        # Raw angles: pins 1 and 2 at +pi and -pi (dy = +0.0, -0.0); 3 still, 4 missing.
        np.testing.assert_allclose(ref, out, atol=1e-6)


def test_pins_without_an_angle_get_exactly_zero_and_right_angles_exactly_half_pi():
    """Still and missing pins give dtheta == 0.0 exactly; pins at 90 deg to the mean give +-pi/2 (float32)."""
    # Velocities (1, 0), (1, 0), (0, 1), (0, -1), still, missing: mean direction +x.
    prev = np.r_[[0.0, 0.0, 0.0, 0.0, 4.0, np.nan], [0.0, 0.0, 0.0, 0.0, 4.0, 0.0]]
    cur = np.r_[[1.0, 1.0, 0.0, 0.0, 4.0, 1.0], [0.0, 0.0, 1.0, -1.0, 4.0, 0.0]]
    pins = np.asarray([[prev, cur]], dtype=np.float32)
    _, session = _features_session(6, "dtheta", True, False)
    out = session.run(None, {"pins": pins})[0][0]
    half = np.float32(np.pi / 2)
    np.testing.assert_array_equal(
        np.asarray([0.0, 0.0, half, -half, 0.0, 0.0], np.float32), out
    )


def test_default_feature_graph_stays_a_few_wide_nodes():
    """Dispatch per node dominates at 127 pins: the default feature graph keeps <= 26 nodes."""
    model = export_velocity_features(127).model
    assert 26 >= len(model.graph.node)


@functools.cache
def _features_session(n_pins: int, variant: str, shift: bool, missing: bool):
    graph = export_velocity_features(
        n_pins, variant=variant, shift_angles=shift, missing_count=missing
    )
    return graph, onnx_session(graph)


# Positions (mm, float32) mixing ordinary values with exact repeats, signed zeros,
# unit steps (velocities like (-1, +-0): angles exactly at +-pi), NaN and inf.
_position = st.one_of(
    st.floats(-100.0, 100.0, width=32),
    st.sampled_from([0.0, -0.0, 1.0, -1.0, np.nan, np.inf, 1e-30]),
)


@st.composite
def pin_frames(draw: st.DrawFn) -> np.ndarray:
    """(batch, 2, 2N) previous/current pin frames with still, missing and antiparallel pins."""
    n = draw(st.integers(1, 6))
    batch = draw(st.integers(1, 3))
    values = draw(st.lists(_position, min_size=batch * 4 * n, max_size=batch * 4 * n))
    pins = np.asarray(values, dtype=np.float32).reshape(batch, 2, 2 * n)
    still = np.asarray(draw(st.lists(st.booleans(), min_size=2 * n, max_size=2 * n)))
    pins[:, 1, still] = pins[:, 0, still]  # zero velocity in these coordinates
    return pins


@settings(max_examples=150, deadline=None)
@given(
    pins=pin_frames(),
    variant=st.sampled_from(["dr_dtheta", "dr", "dtheta"]),
    shift=st.booleans(),
    missing=st.booleans(),
)
def test_in_graph_features_equal_velocity_features(
    pins: np.ndarray, variant: str, shift: bool, missing: bool
):
    """NaN/inf pins, still pins, signed zeros and angles at +-pi: graph == numpy (angles circularly)."""
    n = pins.shape[-1] // 2
    graph, session = _features_session(n, variant, shift, missing)
    out = run_graph(graph, pins, session=session)
    ref = _features_of(pins, variant=variant, shift_angles=shift, missing_count=missing)
    assert ref.shape == out.shape
    assert np.isfinite(out).all()
    n_dr = n if variant != "dtheta" else 0
    n_th = n if variant != "dr" else 0
    np.testing.assert_allclose(ref[:, :n_dr], out[:, :n_dr], rtol=1e-6, atol=1e-5)
    theta = slice(n_dr, n_dr + n_th)
    assert 1e-5 >= _circular(out[:, theta] - ref[:, theta]).max(initial=0.0)
    if not shift:  # raw atan2 keeps numpy's sign-of-zero rule exactly, even at -pi
        np.testing.assert_allclose(ref[:, theta], out[:, theta], atol=1e-5)
    if missing:
        np.testing.assert_array_equal(ref[:, -1], out[:, -1])


@settings(max_examples=200, deadline=None)
@given(
    dxy=st.lists(
        st.tuples(st.floats(-10, 10), st.floats(-10, 10)), min_size=1, max_size=8
    )
)
@example(dxy=[(0.0, 5e-324), (1.0, 1.0)])  # a subnormal velocity (found by Hypothesis)
@example(
    dxy=[(0.0, 1.0), (5e-324, 5e-324)]
)  # hypot rounds a subnormal: v / r is not unit
def test_shifted_angle_is_atan2_of_cross_and_dot_with_the_mean_direction(dxy):
    """wrap(theta - circular mean) == atan2(m x v, m . v) with m the sum of unit velocities."""
    v = np.asarray(dxy, dtype=np.float64)
    r = np.hypot(v[:, 0], v[:, 1])
    has = r > 0
    theta = np.arctan2(v[:, 1], v[:, 0])
    shifted = wrap_angle(theta - circular_mean(theta, where=has))
    # the reference's unit vectors from the angle: v / hypot(v) is not unit for a
    # subnormal v (hypot rounds 5e-324 * sqrt(2) to 5e-324)
    u = np.column_stack([np.cos(theta), np.sin(theta)])[has]
    c, s = u.sum(axis=0) if has.any() else (0.0, 0.0)
    if np.hypot(c, s) / max(int(has.sum()), 1) <= 1e-9:
        c, s = 1.0, 0.0
    unit = np.zeros_like(v)
    unit[has] = u  # scale-free: a subnormal velocity keeps its direction
    via_cross = np.arctan2(
        c * unit[:, 1] - s * unit[:, 0], c * unit[:, 0] + s * unit[:, 1]
    )
    assert 1e-9 >= _circular(shifted[has] - via_cross[has]).max(initial=0.0)


def test_bad_exports_are_refused_by_name():
    """Three classes, or features that do not fit the variant, raise ExportError."""
    X, y = make_classification(
        n_samples=60, n_features=5, n_informative=3, n_classes=3, random_state=0
    )
    with pytest.raises(ExportError, match="two classes"):
        export_tactip_svm(TacTipSVM(C=1.0).fit(X, y))
    svm = TacTipSVM(C=1.0).fit(X, y % 2)
    with pytest.raises(ExportError, match="do not fit variant='dr_dtheta'"):
        export_tactip_svm(svm, with_features=True)
    graph = export_tactip_svm(svm, with_features=True, variant="dr")
    assert ("batch", 2, 10) == graph.input_shape
