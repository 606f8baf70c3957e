"""Exporter of the learned SlipTack speed regressor: a window of nib samples in, speed out.

:class:`~slipkit.families.sliptack.spectral.SpectralSpeedRegressor` computes, every ``hop``
samples, features of the last ``W = window`` samples and maps them to a speed (mm/s)
with a scikit-learn regressor. The graph holds all of it, on the window
``(batch, W, 1)`` float32 (oldest first), as the analytic speed graph
(:mod:`slipkit.families.sliptack.export.speed`) does:

1. **f_d** - the internal analytic estimator's dominant frequency (``physics_``),
   built by the analytic graph's own nodes (``slipkit.families.sliptack.export.speed._frequency``:
   moving-average detrend, Hamming, two-stage DFT, eqs. 6-7); NaN (no peak) -> 0, as
   the batch features;
2. **spectrum** - non-finite samples -> 0 (as the batch features), the least-squares
   line removed (``scipy.signal.detrend``'s ``linear``: two ``MatMul`` with the
   orthonormal basis of ``[1, t]``), Hamming, and the real DFT of length ``W`` with
   the same factorised matrices (:func:`slipkit.families.sliptack.export.speed.dft_matrices`);
3. **band powers** - one ``MatMul`` with the constant bin -> band membership, then
   ``log10(band / total + 1e-12)``;
4. **peak frequencies** - strict local maxima of the power spectrum (interior bins,
   as ``scipy.signal.find_peaks``), a ``TopK`` of their powers (strongest first, ties:
   the lower bin), their bin frequencies, 0 where there are fewer peaks;
5. **regressor** - the fitted ``regressor_`` converted by skl2onnx (float32 features;
   ``HistGradientBoostingRegressor`` as a ``TreeEnsembleRegressor``, the ridge
   pipeline as ``Sub``/``Div``/``MatMul``).

The score is the speed (mm/s) at the window's last sample, float32 ``(batch,)``.

Precision. The DFT products run in ``dft_dtype`` (float32 by default, as the analytic
graph: the power spectrum to ~1e-6 relative) and the regressor on float32 features
(skl2onnx's tree ensembles take float32; their thresholds are float32 too). A tree
split whose threshold lies within that rounding of a feature can go the other way,
changing the speed by one leaf's value; the parity tests and ``slipkit export`` count
such calls.

skl2onnx 1.20 cannot convert a ``HistGradientBoostingRegressor`` under scikit-learn
1.9 and onnx 1.23: it passes a Python ``bool`` for the leaves'
``nodes_missing_value_tracks_true`` into an ``ints`` attribute, which onnx's
``make_attribute`` refuses. :func:`_tree_bool_fix` casts that one argument to ``int``
while converting (a small shim around skl2onnx's own converter rather than a
hand-written tree exporter).

Decision. As for the analytic speed, :class:`SpectralSlipDetector` wraps the fitted
regressor with a speed threshold (``speed >= threshold``, mm/s): it is what
``slipkit export`` deploys for a SlipTack run of ``spectral_gbr``
(:mod:`slipkit.export.deploy`, task ``SlipTackSpeed``).
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from typing import Any

import numpy as np
import onnx
from numpy.typing import ArrayLike, NDArray
from onnx import compose, helper
from sklearn.utils.validation import check_is_fitted

from slipkit.export._graph import DOUBLE, FLOAT, GraphBuilder
from slipkit.export.detectors import SCORE, WINDOW_INPUT, DetectorGraph
from slipkit.export.registry import (
    DEFAULT_OPSET,
    IR_VERSION,
    ExportError,
    check_opset,
    finalize_model,
    producers,
    register_exporter,
)
from slipkit.families.sliptack.export.detector import SpeedSlipDetector
from slipkit.families.sliptack.export.speed import (
    _factor,
    _frequency,
    _peak_frequency,
    _reduce,
    _slice,
    dft_matrices,
)
from slipkit.families.sliptack.spectral import SpectralSpeedRegressor
from slipkit.families.sliptack.speed import StickSlipSpeed

FloatArray = NDArray[np.float64]
_FEATURES = "spectral_features"


@contextlib.contextmanager
def _tree_bool_fix() -> Iterator[None]:
    """skl2onnx's tree-node helper with ``nodes_missing_value_tracks_true`` as an int.

    See the module notes: skl2onnx 1.20 passes ``False`` for a leaf, which onnx 1.23
    refuses in an ``ints`` attribute. Restored on exit.
    """
    from skl2onnx.common import tree_ensemble

    original = tree_ensemble.add_node

    def add_node(*args: Any, **kwargs: Any) -> Any:
        key = "nodes_missing_value_tracks_true"
        if key in kwargs:
            kwargs[key] = int(kwargs[key])
        return original(*args, **kwargs)

    tree_ensemble.add_node = add_node
    try:
        yield
    finally:
        tree_ensemble.add_node = original


def _linear_detrend_basis(w: int) -> FloatArray:
    """Orthonormal basis ``(w, 2)`` of the constant and the line over ``w`` samples."""
    a = np.column_stack([np.ones(w), np.arange(w, dtype=np.float64)])
    q, _ = np.linalg.qr(a)
    return q


def band_matrix(est: SpectralSpeedRegressor) -> FloatArray:
    """Bin -> band membership ``(W // 2 + 1, n_bands)`` of the regressor's band powers."""
    w, rate = int(est.window), float(est.rate_hz)
    freqs = np.fft.rfftfreq(w, 1.0 / rate)
    lo, hi = (float(b) for b in est.band_hz)
    edges = np.geomspace(lo, min(hi, rate / 2), int(est.n_bands) + 1)
    band = np.digitize(freqs, edges) - 1
    return (band[:, None] == np.arange(int(est.n_bands))[None, :]).astype(np.float64)


def _power(g: GraphBuilder, xw: str, w: int, dft_dtype: str) -> str:
    """The power spectrum ``(b, W // 2 + 1)``, bins in order, of the windows ``xw`` (b, W)."""
    f1, gm, n1, k2n = dft_matrices(w)
    n2 = w // n1
    dt = np.float32 if dft_dtype == "float32" else np.float64
    if dt is np.float32:
        xw = g.op("Cast", xw, to=FLOAT)
    grid = g.op("Reshape", xw, g.const([-1, n1, n2], np.int64), stem="grid")
    a = g.op("MatMul", g.const(f1, dt), grid, stem="stage1")
    a = g.op("Reshape", a, g.const([-1, 2, n1, 1, n2], np.int64))
    g2 = np.stack([gm[:, :n2, :], gm[:, n2:, :]])
    y = g.op("MatMul", a, g.const(g2, dt), stem="stage2")
    y = g.op("ReduceSum", y, g.const([1], np.int64), keepdims=0)
    y = g.op("Reshape", y, g.const([-1, n1, 2, k2n], np.int64))
    y = g.op("Mul", y, y)
    power = g.op("ReduceSum", y, g.const([2], np.int64), keepdims=0)
    power = g.op("Reshape", power, g.const([-1, n1 * k2n], np.int64))
    if dt is np.float32:
        power = g.op("Cast", power, to=DOUBLE)
    ks = (np.arange(n1)[:, None] + n1 * np.arange(k2n)[None, :]).reshape(-1)
    pos = np.argsort(ks)[: w // 2 + 1]  # pos[k]: where bin k sits
    return g.op("Gather", power, g.const(pos, np.int64), axis=1, stem="power")


def twiddle_dft_matrices(
    nfft: int,
) -> tuple[FloatArray, FloatArray, FloatArray, int, int]:
    """Constants of a real DFT of length ``nfft`` in two GEMMs and one twiddle product.

    Cooley-Tukey with ``nfft = N1 N2`` (:func:`slipkit.families.sliptack.export.speed.dft_matrices`'s
    factors) and the signal reshaped row-major to ``X[n1, n2] = x[N2 n1 + n2]``:

    1. ``A = F1 @ X``, ``F1`` of shape ``(2 N1, N1)`` with rows interleaved per
       ``k1`` (row ``2 k1`` the cosines of ``2 pi n1 k1 / N1``, row ``2 k1 + 1`` the
       negative sines), so ``A`` reshapes to ``(N1, 2, N2)``: (re, im) per ``k1``;
    2. the twiddle ``exp(-2 pi i n2 k1 / nfft)`` as one broadcast product with ``T``
       ``(N1, 2, 2, N2)``: per ``k1`` the row ``[re c, re s, im s, im c]`` (``c, s``
       the twiddle's cosine and sine), length ``4 N2``;
    3. ``Y = Z @ W2`` with ``W2 = [M1; -M2; M1; M2]`` ``(4 N2, 2 K2)``, ``M1 = [Gc,
       Gs]``, ``M2 = [-Gs, Gc]`` the length-``N2`` DFT ``exp(-2 pi i n2 k2 / N2) = Gc +
       i Gs``: ``[Y_re, Y_im]`` of bin ``k1 + N1 k2``, ``k2 < K2``.

    Against :func:`~slipkit.families.sliptack.export.speed.dft_matrices` (a separate ``(2 N2, 2 K2)``
    block per ``k1``, i.e. ``4 N1`` GEMMs of one row per window), step 3 is one GEMM of
    ``N1`` rows per window: the same products, far fewer calls.

    Returns
    -------
    F1 : ndarray (2 N1, N1)
    T : ndarray (N1, 2, 2, N2)
    W2 : ndarray (4 N2, 2 K2)
    n1, k2 : int
        ``N1`` and ``K2``.
    """
    n1, n2 = _factor(int(nfft))
    k1 = np.arange(n1)
    a1 = 2.0 * np.pi * np.outer(k1, k1) / n1
    f1 = np.stack([np.cos(a1), -np.sin(a1)], axis=1).reshape(2 * n1, n1)
    th = 2.0 * np.pi * np.outer(k1, np.arange(n2)) / nfft  # (N1, N2)
    c, s = np.cos(th), np.sin(th)
    t = np.stack([np.stack([c, s], axis=1), np.stack([s, c], axis=1)], axis=1)
    k2n = (nfft // 2) // n1 + 1
    ang = -2.0 * np.pi * np.outer(np.arange(n2), np.arange(k2n)) / n2
    gc, gs = np.cos(ang), np.sin(ang)
    m1 = np.concatenate([gc, gs], axis=1)
    m2 = np.concatenate([-gs, gc], axis=1)
    return f1, t, np.concatenate([m1, -m2, m1, m2]), n1, k2n


def _twiddle_power(g: GraphBuilder, xw: str, nfft: int, dt: Any) -> str:
    """Power spectra ``(B, N1 K2)`` in ``dt`` of the rows ``xw`` ``(B, nfft)`` (already
    in ``dt``), bin ``k1 + N1 k2`` at ``k1 K2 + k2`` (as ``sliptack._frequency``)."""
    f1, t, w2, n1, k2n = twiddle_dft_matrices(nfft)
    n2 = nfft // n1
    i64 = np.int64
    grid = g.op("Reshape", xw, g.const([-1, n1, n2], i64), stem="grid")
    a = g.op("MatMul", g.const(f1, dt), grid, stem="stage1")  # (B, 2 N1, N2)
    a = g.op("Reshape", a, g.const([-1, n1, 2, 1, n2], i64))
    z = g.op("Mul", a, g.const(t, dt), stem="twiddled")  # (B, N1, 2, 2, N2)
    z = g.op("Reshape", z, g.const([-1, 4 * n2], i64))
    y = g.op("MatMul", z, g.const(w2, dt), stem="stage2")  # (B N1, 2 K2)
    y = g.op("Reshape", y, g.const([-1, n1, 2, k2n], i64))
    power = _reduce(g, "ReduceSumSquare", y, (2,), 0)  # (B, N1, K2)
    return g.op("Reshape", power, g.const([-1, n1 * k2n], i64), stem="power")


def _ma_windowed(g: GraphBuilder, x: str, physics: StickSlipSpeed) -> str:
    """The analytic estimator's detrended, tapered window (``sliptack._frequency``'s
    first two steps, the same nodes): ``x - x[0]`` minus its edge-padded moving
    average over ``detrend_frames``, times the Hamming window; NaN stays NaN."""
    w = int(physics.window)
    s = min(int(physics.detrend_frames), w)
    xc = g.op("Sub", x, _slice(g, x, 0, 1, 1), stem="xc")
    left = s // 2
    pads = g.const([0, left, 0, s - left], np.int64)
    padded = g.op("Pad", xc, pads, mode="edge", stem="padded")
    cs0 = g.op("CumSum", padded, g.const(1, np.int64), exclusive=1, stem="cs0")
    diff = g.op("Sub", _slice(g, cs0, s, s + w, 1), _slice(g, cs0, 0, w, 1))
    trend = g.op("Div", diff, g.const(float(s), np.float64), stem="trend")
    resid = g.op("Sub", xc, trend, stem="resid")
    return g.op("Mul", resid, g.const(np.hamming(w), np.float64), stem="windowed_fd")


def _shares_dft(est: SpectralSpeedRegressor) -> bool:
    """Whether the ``f_d`` spectrum has the feature spectrum's length (no zero padding)."""
    phys = est.physics_
    return int(phys.window) == int(est.window) and int(phys.pad_factor) == 1


def _feature_graph(
    est: SpectralSpeedRegressor,
    opset: int,
    dft_dtype: str,
    shared_dft: bool = True,
) -> onnx.ModelProto:
    """Windows ``(batch, W, 1)`` float32 -> the regressor's features ``(batch, F)`` float32.

    ``shared_dft``: both spectra (``f_d``'s and the features') through one DFT
    (:func:`twiddle_dft_matrices`, the two tapered windows stacked); False: each its own
    DFT (``sliptack._frequency`` for ``f_d``, :func:`_power` for the features), the
    slower graph, kept for the side-by-side benchmark.
    """
    w, rate = int(est.window), float(est.rate_hz)
    n_bands, n_peaks = int(est.n_bands), int(est.n_peaks)
    g = GraphBuilder("spectral_features", opset)
    x = g.op(
        "Reshape",
        g.op("Cast", WINDOW_INPUT, to=DOUBLE),
        g.const([-1, w], np.int64),
        stem="x",
    )
    zero = g.const(0.0, np.float64)
    # spectrum of the features: non-finite -> 0, linear detrend, Hamming
    bad = g.op("IsNaN", g.op("Sub", x, x))  # NaN exactly for NaN and +-inf
    xf = g.op("Where", bad, zero, x)
    q = _linear_detrend_basis(w)
    coef = g.op("MatMul", xf, g.const(q, np.float64))
    # the line times the taper, subtracted from the tapered window
    taper = np.hamming(w)
    xw = g.op(
        "Sub",
        g.op("Mul", xf, g.const(taper, np.float64)),
        g.op("MatMul", coef, g.const(q.T * taper[None, :], np.float64)),
        stem="windowed",
    )
    use_fd = bool(getattr(est, "f_d_feature", True))  # runs saved before it: True
    fd: str | None = None
    if not use_fd:
        # no f_d feature: the features' spectrum alone, by the two-GEMM DFT
        dt = np.float32 if dft_dtype == "float32" else np.float64
        if dt is np.float32:
            xw = g.op("Cast", xw, to=FLOAT)
        pw = _twiddle_power(g, xw, w, dt)
        n1 = int(_factor(w)[0])
        k2n = (w // 2) // n1 + 1
        ks = (np.arange(n1)[:, None] + n1 * np.arange(k2n)[None, :]).reshape(-1)
        if dt is np.float32:
            pw = g.op("Cast", pw, to=DOUBLE)
        power = g.op(
            "Gather", pw, g.const(np.argsort(ks)[: w // 2 + 1], np.int64), axis=1
        )
    elif shared_dft and _shares_dft(est):
        # 1.+2. one DFT of both tapered windows, f_d's (moving-average detrend, NaN
        # kept: every bin NaN, f_d NaN, as the batch estimator) and the features'
        # (each row of the stacked GEMMs is its own window: no mixing)
        dt = np.float32 if dft_dtype == "float32" else np.float64
        i64 = np.int64
        both = g.op(
            "Concat",
            g.op("Unsqueeze", _ma_windowed(g, x, est.physics_), g.const([1], i64)),
            g.op("Unsqueeze", xw, g.const([1], i64)),
            axis=1,
        )  # (b, 2, W)
        if dt is np.float32:
            both = g.op("Cast", both, to=FLOAT)
        pw = _twiddle_power(g, g.op("Reshape", both, g.const([-1, w], i64)), w, dt)
        n1 = int(_factor(w)[0])
        k2n = (w // 2) // n1 + 1
        pw = g.op("Reshape", pw, g.const([-1, 2, n1 * k2n], i64))
        ks = (np.arange(n1)[:, None] + n1 * np.arange(k2n)[None, :]).reshape(-1)
        pos = np.argsort(ks)[: w // 2 + 1]  # pos[k]: where bin k sits
        p_fd = g.op("Gather", pw, g.const(0, i64), axis=1, stem="power_fd")
        fd = _peak_frequency(g, p_fd, pos, n1 * k2n, est.physics_, dt)
        p_ft = g.op("Gather", pw, g.const(1, i64), axis=1)
        if dt is np.float32:
            p_ft = g.op("Cast", p_ft, to=DOUBLE)
        power = g.op("Gather", p_ft, g.const(pos, i64), axis=1, stem="power")
    else:
        # 1. f_d of the internal analytic estimator by the analytic graph's nodes
        fd = _frequency(g, x, est.physics_, dft_dtype)
        # 2. the features' DFT
        power = _power(g, xw, w, dft_dtype)  # (b, W // 2 + 1)
    if fd is not None:
        fd = g.op("Where", g.op("IsNaN", fd), zero, fd)  # NaN -> 0, as batch features
        fd = g.op("Unsqueeze", fd, g.const([1], np.int64), stem="f_d")
    parts = []
    if n_bands:
        # 3. log relative band powers
        bands = g.op("MatMul", power, g.const(band_matrix(est), np.float64))
        total = g.op(
            "Add",
            g.op("ReduceSum", bands, g.const([1], np.int64), keepdims=1),
            g.const(1e-30, np.float64),
        )
        rel = g.op("Add", g.op("Div", bands, total), g.const(1e-12, np.float64))
        parts.append(
            g.op(
                "Div",
                g.op("Log", rel),
                g.const(np.log(10.0), np.float64),
                stem="log_bands",
            )
        )
    if n_peaks:
        # 4. the strongest strict local maxima (interior bins 1 .. W // 2 - 1)
        last = w // 2
        i64 = np.int64

        def bins(lo: int) -> str:
            return g.op(
                "Slice",
                power,
                g.const([lo], i64),
                g.const([lo + last - 1], i64),
                g.const([1], i64),
            )

        mid = bins(1)
        peak = g.op("And", g.op("Greater", mid, bins(0)), g.op("Greater", mid, bins(2)))
        score = g.op("Where", peak, mid, g.const(-1.0, np.float64))
        k = min(n_peaks, last - 1)
        top, idx = g._fresh("top"), g._fresh("top_idx")
        g.nodes.append(
            helper.make_node(
                "TopK",
                [score, g.const([k], i64)],
                [top, idx],
                axis=-1,
                largest=1,
                sorted=1,
            )
        )
        valid = g.op("Cast", g.op("Greater", top, g.const(-0.5, np.float64)), to=DOUBLE)
        hz = g.op(
            "Mul",
            g.op("Add", g.op("Cast", idx, to=DOUBLE), g.const(1.0, np.float64)),
            g.const(rate / w, np.float64),
        )
        peaks = g.op("Mul", hz, valid, stem="peak_hz")
        if n_peaks > k:  # fewer interior bins than peaks asked for: zeros, as batch
            pad = g.const([0, 0, 0, n_peaks - k], i64)
            peaks = g.op("Pad", peaks, pad)
        parts.append(peaks)
    if fd is not None:
        parts.append(fd)
    feats = g.op("Concat", *parts, axis=1)
    g.nodes.append(helper.make_node("Cast", [feats], [_FEATURES], to=FLOAT))
    return g.build(
        [helper.make_tensor_value_info(WINDOW_INPUT, FLOAT, ["batch", w, 1])],
        [
            helper.make_tensor_value_info(
                _FEATURES, FLOAT, ["batch", n_bands + n_peaks + int(use_fd)]
            )
        ],
        doc="SlipTack window -> band powers, peak frequencies, f_d",
    )


def _regressor_graph(est: SpectralSpeedRegressor, opset: int) -> onnx.ModelProto:
    """skl2onnx's graph of ``regressor_`` on float32 features; output ``score`` (batch,)."""
    from skl2onnx import to_onnx
    from skl2onnx.common.data_types import FloatTensorType

    n = int(est.n_bands) + int(est.n_peaks) + int(getattr(est, "f_d_feature", True))
    with _tree_bool_fix():
        model = to_onnx(
            est.regressor_,
            initial_types=[(_FEATURES, FloatTensorType([None, n]))],
            target_opset={"": opset, "ai.onnx.ml": 3},
        )
    graph = model.graph
    out = graph.output[0].name
    graph.initializer.append(
        helper.make_tensor("score_shape", onnx.TensorProto.INT64, [1], [-1])
    )
    graph.node.append(helper.make_node("Reshape", [out, "score_shape"], [SCORE]))
    del graph.output[:]
    graph.output.append(helper.make_tensor_value_info(SCORE, FLOAT, ["batch"]))
    model.ir_version = IR_VERSION
    return model


def export_spectral_speed(
    estimator: SpectralSpeedRegressor,
    *,
    threshold: float | None = None,
    dft_dtype: str = "float32",
    shared_dft: bool = True,
    opset: int = DEFAULT_OPSET,
) -> DetectorGraph:
    """Export a fitted :class:`SpectralSpeedRegressor` over a window of ``window`` nib samples.

    Parameters
    ----------
    estimator : SpectralSpeedRegressor
        Fitted (``regressor_``, ``physics_``).
    threshold : float or None
        Slip decision ``speed >= threshold`` (mm/s); the graph then has classes
        ``("0", "1")``. None: a regression graph without decision.
    dft_dtype : {"float32", "float64"}
        Precision of the DFT products (the f_d and the feature spectrum).
    shared_dft : bool
        One DFT for both spectra (:func:`twiddle_dft_matrices`; the default, issue
        16's cost fix); False: each spectrum its own DFT (the graph before it).
    opset : int
        Default-domain opset (17 or 18).

    Returns
    -------
    DetectorGraph
        Input ``(batch, window, 1)`` nib samples, oldest first; ``score`` ``(batch,)``
        float32, the speed (mm/s); ``hop`` the estimator's, ``first_decision = window
        - 1``.
    """
    import scipy
    import skl2onnx
    import sklearn

    if not isinstance(estimator, SpectralSpeedRegressor):
        raise ExportError(
            f"export_spectral_speed needs a SpectralSpeedRegressor; got "
            f"{type(estimator).__name__}"
        )
    check_is_fitted(estimator, ["regressor_", "physics_"])
    opset = check_opset(opset)
    if dft_dtype not in ("float32", "float64"):
        raise ExportError(
            f"dft_dtype must be 'float32' or 'float64'; got {dft_dtype!r}"
        )
    w = int(estimator.window)
    n1 = int(dft_matrices(w)[2])
    model = compose.merge_models(
        _feature_graph(estimator, opset, dft_dtype, shared_dft),
        _regressor_graph(estimator, opset),
        io_map=[(_FEATURES, _FEATURES)],
    )
    model.graph.name = "spectral_speed"
    model = finalize_model(model)
    meaning = "SpectralSpeedRegressor predict at the window's last sample (mm/s)" + (
        "" if threshold is None else f"; slip ('1') where score >= {threshold:g} mm/s"
    )
    return DetectorGraph(
        model=model,
        input_name=WINDOW_INPUT,
        input_shape=("batch", w, 1),
        output_names=(SCORE,),
        score_output=SCORE,
        score_meaning=meaning,
        score_method="decision_function" if threshold is not None else "predict",
        opset=opset,
        classes=None if threshold is None else ("0", "1"),
        threshold=None if threshold is None else float(threshold),
        input_meaning=(
            f"the last {w} nib samples at {float(estimator.rate_hz):g} Hz, oldest first"
        ),
        features={
            "kind": "detector_window",
            "detector": type(estimator).__name__,
            "quantity": "speed",
            "unit": "mm/s",
            "model": str(estimator.model),
            "n_bands": int(estimator.n_bands),
            "band_hz": [float(b) for b in estimator.band_hz],
            "n_peaks": int(estimator.n_peaks),
            "dft_factors": [n1, w // n1],
            "dft_dtype": dft_dtype,
            "shared_dft": bool(shared_dft and _shares_dft(estimator)),
            "f_d_feature": bool(getattr(estimator, "f_d_feature", True)),
        },
        producers=producers(
            scipy=scipy.__version__,
            skl2onnx=skl2onnx.__version__,
            **{"scikit-learn": sklearn.__version__},
        ),
        window=w,
        hop=int(estimator.hop),
        first_decision=w - 1,
        strict=False,
    )


class SpectralSlipDetector(SpeedSlipDetector):
    """Slip where the learned SlipTack speed reaches a threshold (mm/s).

    :class:`~slipkit.families.sliptack.export.detector.SpeedSlipDetector` around a fitted
    :class:`SpectralSpeedRegressor` (same rule: ``decision_function`` is the speed,
    ``-inf`` before the first window; slip where ``>= threshold``); its own class so
    that the exporter registry gives it the spectral graph.

    Parameters
    ----------
    speed : SpectralSpeedRegressor
        Fitted.
    threshold : float
        Speed (mm/s) at and above which the object slips.
    """

    def __init__(
        self, *, speed: SpectralSpeedRegressor, threshold: float = 0.0
    ) -> None:
        super().__init__(speed=speed, threshold=threshold)


def export_spectral_slip_detector(
    detector: SpectralSlipDetector,
    *,
    dft_dtype: str = "float32",
    shared_dft: bool = True,
    opset: int = DEFAULT_OPSET,
) -> DetectorGraph:
    """Export a fitted :class:`SpectralSlipDetector`: the speed graph with its threshold."""
    check_is_fitted(detector, "threshold_")
    return export_spectral_speed(
        detector.speed,
        threshold=detector.threshold_,
        dft_dtype=dft_dtype,
        shared_dft=shared_dft,
        opset=opset,
    )


def graph_speeds(out: ArrayLike) -> FloatArray:
    """The graph's score as float64 ``(n,)`` (mm/s)."""
    return np.asarray(out, dtype=np.float64).reshape(-1)


register_exporter(SpectralSpeedRegressor, export_spectral_speed)
register_exporter(SpectralSlipDetector, export_spectral_slip_detector)

__all__ = [
    "SpectralSlipDetector",
    "band_matrix",
    "export_spectral_slip_detector",
    "export_spectral_speed",
    "graph_speeds",
]
