"""Exporter of the SlipTack stick-slip speed estimator: a window of nib samples in, speed out.

:class:`~slipkit.baselines.sliptack.StickSlipSpeed` is analytic and every step of it
has an ONNX form, so the graph holds the whole estimator (``docs/export.md``, *SlipTack
speed*). It takes the last ``W = window`` nib samples, shape ``(batch, W, 1)`` float32,
oldest first, and returns ``score`` ``(batch,)`` float32:

1. **detrend**: the centred ``detrend_frames`` moving average (``mode="nearest"``, as
   :func:`scipy.ndimage.uniform_filter1d`) by an edge ``Pad`` and an exclusive
   ``CumSum`` in float64, after subtracting the window's first sample (exact for float32
   samples; the residual does not change, and a constant window becomes exactly 0);
2. **spectrum**: Hamming window, zero padding to ``nfft = W pad_factor``, and the real
   DFT as a two-stage Cooley-Tukey factorisation ``nfft = N1 N2`` (:func:`dft_matrices`:
   two ``MatMul`` ops with constant cosine / sine matrices, the twiddles folded into the
   second, whose ``N1`` products each take one ``[A_re, A_im]`` row; 1000 = 25 x 40):
   0.13 M multiply-adds instead of the 1 M of one DFT matrix. (The two-GEMM twiddle form
   of :mod:`slipkit.export.spectral` is ~3 us faster here but rounds the twiddled
   values to float32 once more: speeds then differ from the batch by up to 1.5e-6
   relative, over the tests' 1e-6.)
   ONNX's ``DFT`` op is not used (onnxruntime 1.31 runs lengths that are not powers of
   two as an ``O(n^2)`` loop). The two products run in ``dft_dtype`` (float32 by
   default: MLAS's float32 kernels, ~14 us per call less than float64 in
   ``python -m slipkit.export.sliptack``; the power spectrum is then good to ~1e-6
   relative, far below the gaps between the peaks the rule compares);
3. **peaks** (eqs. 6-7): strict local maxima of the power spectrum below the largest
   ``f_max``, the ``min_peak_ratio`` rule (squared, on power) against the largest bin of
   the whole spectrum (DC excluded), then per ``f_max`` a ``TopK`` of the peaks at or
   below it (ties: the lower bin, as the batch sort) and the mean over ``j = 1..n_peaks``
   of the top-``j`` means; ``f_d`` is their mean over the ``f_max`` values with a peak.
   Constants are folded where the float result is the same or within rounding (the
   ratio into the mask of the largest bin, ``1 / n_peaks`` into the frequencies, the
   gate's mean into one ``MatMul``), the harmonic relation runs in float32 (exact
   counts), and the interpolation is one ``Gather`` of the bin triples and one ``(2,
   3)`` ``MatMul`` for the vertex offset's numerator and denominator (96 -> 84 nodes for
   the shipped detector config, with the DFT's; a zero-power neighbour of a peak, never seen in noisy
   data, gets a clipped offset where the batch form's is 0);
4. **speed** (eq. 3 inverted): ``form="paper"`` in closed form; ``form="exact"`` by
   linear interpolation in a table of the batch bisection over the frequencies ``f_d``
   can take (:func:`speed_table`: from the DFT resolution to the largest ``f_max``,
   16384 entries for the default detector, within 1e-7 relative of the bisection). An
   unrolled bisection or Newton iteration is exact too but costs ~8 graph nodes per
   step, and node count, not arithmetic, dominates a batch-1 call.

A window holding NaN / inf makes every DFT bin NaN and a constant window every bin 0:
no bin is then a strict local maximum and ``f_d = 0 / 0 = NaN``, the batch estimator's
NaN. Where the estimator gives NaN (also: no spectral peak, a frequency at or above
saturation) the graph scores :data:`~slipkit.export.detectors.NO_SCORE`, the lowest
float32, read back as NaN by :func:`graph_speeds`. Known differences from the batch
estimator: ``find_peaks`` reports the middle of a flat-topped peak where the graph
needs a strict maximum (equal magnitudes in neighbouring bins do not occur in noisy
signals), and a float64 recording that varies by less than float32 resolution is
constant for the graph (NaN) but not always for the batch form.

Decision. A speed has no slip class; :class:`SpeedSlipDetector` wraps a fitted
estimator with a speed threshold (mm/s): slip (``1``) where ``speed >= threshold``,
no slip where the speed is below it or undefined. Threshold 0 reads "a stick-slip
frequency is present". The wrapper is what ``slipkit export`` deploys
(:mod:`slipkit.export.deploy`, task ``SlipTackSpeed``) and what parity compares with
(:func:`slipkit.export.detectors.check_detector_parity`; the graph's ``window`` /
``hop`` / ``first_decision`` are ``W`` / the estimator's ``hop`` / ``W - 1``, the
batch estimator's estimation instants).

``python -m slipkit.export.sliptack`` prints parity and the time per call on simulated
``sliptack_pull`` recordings.
"""

from __future__ import annotations

import math
from numbers import Real
from typing import Any, ClassVar

import numpy as np
import onnx
from numpy.typing import ArrayLike, NDArray
from onnx import helper
from sklearn.base import BaseEstimator, ClassifierMixin
from sklearn.utils._param_validation import HasMethods, Interval
from sklearn.utils.validation import check_is_fitted

from slipkit.baselines.sliptack import (
    StickSlipSpeed,
    f_max_values,
    gate_first_bin,
    harmonic_relation,
)
from slipkit.export._graph import DOUBLE, FLOAT, GraphBuilder
from slipkit.export.detectors import (
    NO_SCORE,
    SCORE,
    WINDOW_INPUT,
    DetectorGraph,
)
from slipkit.export.registry import (
    DEFAULT_OPSET,
    ExportError,
    producers,
    register_exporter,
)

FloatArray = NDArray[np.float64]
#: Outputs of :func:`export_stick_slip_speed`'s ``quantity`` option.
QUANTITIES = ("speed", "frequency")
_F32_MAX = float(np.finfo(np.float32).max)


def _factor(n: int) -> tuple[int, int]:
    """``n = n1 n2`` with ``n1`` the largest divisor not above sqrt(n) (1 for a prime)."""
    n1 = max(d for d in range(1, math.isqrt(n) + 1) if n % d == 0)
    return n1, n // n1


def dft_matrices(nfft: int) -> tuple[FloatArray, FloatArray, int, int]:
    """The two constant matrices of the graph's real DFT of length ``nfft``.

    With ``nfft = N1 N2`` and the padded signal reshaped row-major to ``X[n1, n2] =
    x[N2 n1 + n2]``, stage 1 is ``A = F1 @ X`` (``F1 = [cos; -sin]`` of ``2 pi n1 k1 /
    N1``, shape ``(2 N1, N1)``) and stage 2, per ``k1``, ``[A_re, A_im] @ G[k1]`` with
    ``G[k1]`` the complex matrix ``exp(-2 pi i n2 (k1 + N1 k2) / nfft)`` (twiddle and
    the length-``N2`` DFT together) written as a real ``(2 N2, 2 K2)`` block, ``k2 <
    K2`` covering the bins up to ``nfft / 2``. The result ``Y[k1, k2]`` is bin ``k1 +
    N1 k2``.

    Returns
    -------
    F1 : ndarray (2 N1, N1)
    G : ndarray (N1, 2 N2, 2 K2)
    n1, k2 : int
        ``N1`` and ``K2``.
    """
    n1, n2 = _factor(int(nfft))
    k1 = np.arange(n1)
    a1 = 2.0 * np.pi * np.outer(k1, k1) / n1
    f1 = np.concatenate([np.cos(a1), -np.sin(a1)])
    k2n = (nfft // 2) // n1 + 1
    ks = k1[:, None] + n1 * np.arange(k2n)[None, :]  # (N1, K2) bin numbers
    ang = -2.0 * np.pi * np.arange(n2)[None, :, None] * ks[:, None, :] / nfft
    gre, gim = np.cos(ang), np.sin(ang)  # (N1, N2, K2)
    g = np.concatenate(
        [
            np.concatenate([gre, gim], axis=2),  # rows of A_re
            np.concatenate([-gim, gre], axis=2),  # rows of A_im
        ],
        axis=1,
    )
    return f1, g, n1, k2n


def _axes(g: GraphBuilder, *axes: int) -> str:
    return g.const(list(axes), np.int64, stem="axes")


def _reduce(
    g: GraphBuilder, op: str, v: str, axes: tuple[int, ...], keepdims: int
) -> str:
    """A reduction over ``axes``: an input from opset 18 (13 for ReduceSum), else an attribute."""
    if op == "ReduceSum" or g.opset >= 18:
        return g.op(op, v, _axes(g, *axes), keepdims=keepdims)
    return g.op(op, v, axes=list(axes), keepdims=keepdims)


def _d(g: GraphBuilder, value: Any) -> str:
    return g.const(value, np.float64)


def _slice(g: GraphBuilder, v: str, start: int, stop: int, axis: int) -> str:
    i64 = np.int64
    return g.op("Slice", v, g.const([start], i64), g.const([stop], i64), _axes(g, axis))


def _frequency(g: GraphBuilder, x: str, est: StickSlipSpeed, dft_dtype: str) -> str:
    """Nodes computing ``f_d`` (Hz, float64, NaN when undefined) of the windows ``x`` (b, W).

    Node count matters more than arithmetic here (a few hundred ns per node at batch 1):
    comparisons run on the power spectrum (the same order as the magnitude), and a
    non-finite or constant window needs no test of its own -- a NaN or inf sample makes
    every DFT bin NaN and a constant window every bin 0, so no bin is a strict local
    maximum and ``f_d`` is ``0 / 0 = NaN``, the batch estimator's value.
    """
    w = int(est.window)
    nfft = w * int(est.pad_factor)
    s = min(int(est.detrend_frames), w)
    # 1. detrend: the residual is invariant to a constant shift; subtracting the first
    # sample (exact in float64 for float32 samples) keeps the cumulative sums small and
    # makes a constant window exactly 0.
    xc = g.op("Sub", x, _slice(g, x, 0, 1, 1), stem="xc")
    left = s // 2  # uniform_filter1d's centre, for odd and even sizes
    # edge padding, one extra sample on the right so the exclusive cumsum has W + s values
    pads = g.const([0, left, 0, s - left], np.int64)
    padded = g.op("Pad", xc, pads, mode="edge", stem="padded")
    cs0 = g.op("CumSum", padded, g.const(1, np.int64), exclusive=1, stem="cs0")
    diff = g.op("Sub", _slice(g, cs0, s, s + w, 1), _slice(g, cs0, 0, w, 1))
    trend = g.op("Div", diff, _d(g, float(s)), stem="trend")
    resid = g.op("Sub", xc, trend, stem="resid")
    # 2. Hamming window, zero padding, two-stage real DFT (dft_matrices)
    xw = g.op("Mul", resid, _d(g, np.hamming(w)), stem="windowed")
    if nfft > w:
        xw = g.op("Pad", xw, g.const([0, 0, 0, nfft - w], np.int64), stem="zero_padded")
    f1, gm, n1, k2n = dft_matrices(nfft)
    n2 = nfft // n1
    dt = np.float32 if dft_dtype == "float32" else np.float64
    if dt is np.float32:
        xw = g.op("Cast", xw, to=FLOAT)
    grid = g.op("Reshape", xw, g.const([-1, n1, n2], np.int64), stem="grid")
    # F1's rows interleaved per k1 (cos row, then -sin row), so that A reshapes to
    # (b, N1, 1, 2 N2): [A_re, A_im] of each k1 as one row, and stage 2 is N1 products
    # of one 2 N2 row by G[k1] (no sum of separate re / im halves: one node and half
    # the batched products fewer than the split form, the same constants and float
    # roundings as before, so the same spectrum)
    f1i = f1.reshape(2, n1, n1).transpose(1, 0, 2).reshape(2 * n1, n1)
    a = g.op("MatMul", g.const(f1i, dt), grid, stem="stage1")  # (b, 2 N1, N2)
    a = g.op("Reshape", a, g.const([-1, n1, 1, 2 * n2], np.int64))
    y = g.op("MatMul", a, g.const(gm, dt), stem="stage2")  # (b, N1, 1, 2 K2)
    y = g.op("Reshape", y, g.const([-1, n1, 2, k2n], np.int64))
    power = _reduce(g, "ReduceSumSquare", y, (2,), 0)  # (b, N1, K2), bin k1 + N1 k2
    power = g.op("Reshape", power, g.const([-1, n1 * k2n], np.int64), stem="power")
    last = nfft // 2
    ks = (np.arange(n1)[:, None] + n1 * np.arange(k2n)[None, :]).reshape(-1)
    pos = np.argsort(ks)[: last + 1]  # pos[k]: where bin k sits in ``power``
    return _peak_frequency(g, power, pos, n1 * k2n, est, dt)


def _peak_frequency(
    g: GraphBuilder,
    power: str,
    pos: NDArray[np.intp],
    n_power: int,
    est: StickSlipSpeed,
    dt: type[np.floating[Any]],
) -> str:
    """Nodes from the power spectrum ``power`` (b, n_power) to ``f_d`` (Hz, float64, NaN).

    ``pos[k]`` is where DFT bin ``k`` (0 .. nfft / 2) sits along ``power``'s axis 1;
    other entries are ignored. Steps 3 (peaks, eqs. 6-7) and the gate of the module
    docstring.
    """
    rate = float(est.rate_hz)
    nfft = int(est.window) * int(est.pad_factor)
    last = nfft // 2
    # 3. peaks: interior bins 1..c with freq <= the largest f_max (find_peaks skips the ends)
    freqs = np.fft.rfftfreq(nfft, 1.0 / rate)
    fmax = f_max_values(tuple(est.f_max_range), float(est.f_max_step))
    c = min(int(np.sum(freqs <= fmax[-1])) - 1, last - 1)
    if c < 1:
        raise ExportError(
            f"StickSlipSpeed export: no DFT bin between 0 Hz and f_max {fmax[-1]:g} Hz "
            f"(resolution {rate / nfft:g} Hz); widen window or f_max_range"
        )

    def bins(lo: int) -> str:
        return g.op("Gather", power, g.const(pos[lo : lo + c], np.int64), axis=1)

    mid = bins(1)
    # the largest magnitude of the spectrum, DC excluded (bins beyond nfft / 2 masked)
    # (min_peak_ratio squared, on power, folded into the mask: the largest of
    # ratio2 x power is ratio2 x the largest, the same float product)
    ratio2 = float(est.min_peak_ratio) ** 2  # on power
    spectrum = np.isin(np.arange(n_power), pos[1:]) * ratio2
    masked = g.op("Mul", power, g.const(spectrum, dt))
    gmax_r = _reduce(g, "ReduceMax", masked, (1,), 1)
    lower, upper = bins(0), bins(2)
    peak = g.op(
        "And",
        g.op("And", g.op("Greater", mid, lower), g.op("Greater", mid, upper)),
        g.op("GreaterOrEqual", mid, gmax_r),
        stem="peak",
    )  # (b, c)
    gate = float(getattr(est, "min_peak_to_mean", 0.0) or 0.0)
    if gate > 0.0:
        # no stick-slip oscillation: the largest bin of the gate band is not gate x
        # the band's mean power (gate_first_bin); then no peak counts, f_d is NaN
        k0 = gate_first_bin(nfft, min(int(est.detrend_frames), int(est.window)))
        in_band = np.isin(np.arange(n_power), pos[k0:])
        band = g.op("Mul", power, g.const(in_band, dt))
        # gate x the band's mean power: one MatMul with the weights gate / n_band
        mean = g.op(
            "MatMul", power, g.const((in_band * (gate / (last + 1 - k0)))[:, None], dt)
        )
        bmax = _reduce(g, "ReduceMax", band, (1,), 1)
        peak = g.op("And", peak, g.op("GreaterOrEqual", bmax, mean), stem="gated")
    if est.harmonics == "fundamental":
        # a counted peak at ~m x a lower counted peak is a harmonic: one MatMul with a
        # constant (c, c) relation of the bins (harmonic_mask's rule on bin numbers)
        # (in float32: counts of a few 0/1 products are exact, and MLAS's float32
        # kernel is the fast one)
        rel = harmonic_relation(np.arange(1, c + 1), float(est.harmonic_tol))
        hits = g.op(
            "MatMul",
            g.op("Cast", peak, to=FLOAT),
            g.const(rel.astype(np.float32), np.float32),
        )
        peak = g.op(
            "And",
            peak,
            g.op("Less", hits, g.const(0.5, np.float32)),
            stem="fundamental",
        )
    # a peak's power, -1 for other bins; per f_max, -inf above it (one broadcast Add:
    # the (n_fmax, c) tensors are the graph's largest after the DFT)
    score = g.op("Where", peak, mid, g.const(-1.0, dt))
    below = freqs[1 : c + 1][None, :] <= fmax[:, None]  # (n_fmax, c)
    ranked = g.op(
        "Add",
        g.op("Unsqueeze", score, _axes(g, 1)),
        g.const(np.where(below, 0.0, -np.inf), dt),
        stem="ranked",
    )
    k = min(int(est.n_peaks), c)
    top, idx = _topk(g, ranked, k)  # (b, n_fmax, k), largest first, ties: lower bin
    is_valid = g.op("GreaterOrEqual", top, g.const(0.0, dt))
    valid = g.op("Cast", is_valid, to=DOUBLE, stem="valid")
    # every frequency is divided by n_peaks here (folded into constants), so that
    # eq. 6-7's mean below is one Div
    n_peaks = int(est.n_peaks)
    bin_hz = float(freqs[1] - freqs[0])
    if est.interpolate:
        # the parabola through the log powers (= 2 log magnitudes: the vertex offset is
        # the same) of each bin and its neighbours, as parabolic_offset, in few nodes:
        # one Gather of the (bin - 1, bin, bin + 1) powers (b, 3, c), their log (powers
        # clamped to the smallest normal float32: a zero bin has a finite log), then
        # one constant MatMul (2, 3) for the offset's numerator ``h (a - c)`` and its
        # denominator ``a - 2 b + c`` (h = half a bin / n_peaks, so the offset comes out
        # in Hz / n_peaks), Clip to +-h. No den < 0 test: a strict maximum has one, and
        # other bins (possibly 0 / 0) are dropped by the ``Where`` on ``valid`` below.
        trip = g.op(
            "Gather",
            power,
            g.const(np.stack([pos[d : d + c] for d in (0, 1, 2)]), np.int64),
            axis=1,
        )  # (b, 3, c)
        logp = g.op("Log", g.op("Max", trip, g.const(np.finfo(np.float32).tiny, dt)))
        if dt is np.float32:
            logp = g.op("Cast", logp, to=DOUBLE)
        half = 0.5 * bin_hz / n_peaks
        nd = g.op("MatMul", _d(g, [[half, 0.0, -half], [1.0, -2.0, 1.0]]), logp)
        num, den = g._fresh("num"), g._fresh("den")
        split = {"num_outputs": 2} if g.opset >= 18 else {}
        g.nodes.append(helper.make_node("Split", [nd], [num, den], axis=1, **split))
        off = g.op("Clip", g.op("Div", num, den), _d(g, -half), _d(g, half))
        fb = g.op(
            "Add",
            off,
            _d(g, np.arange(1, c + 1, dtype=np.float64) * bin_hz / n_peaks),
            stem="peak_hz",
        )  # (b, 1, c), Hz / n_peaks
        fb = g.op("Expand", fb, g.const([1, len(fmax), c], np.int64))
        ftop = g.op(
            "Where", is_valid, g.op("GatherElements", fb, idx, axis=2), _d(g, 0.0)
        )
    else:
        ftop = g.op(
            "Mul",
            g.op("Gather", _d(g, freqs[1 : c + 1] / n_peaks), idx, axis=0),
            valid,
        )
    n_valid = g.op("ReduceSum", valid, _axes(g, 2), keepdims=1, stem="n_valid")  # L
    n_div = g.op("Max", n_valid, _d(g, 1.0))
    csf = g.op("CumSum", ftop, g.const(2, np.int64), stem="csf")
    # top-j mean: cumsum_j / j while j <= L, the mean of all L beyond (eq. 6, as batch);
    # an f_max without a peak adds 0 to the sum and 0 to the count (eq. 7's nanmean)
    denom = g.op("Min", _d(g, np.arange(1, k + 1, dtype=np.float64)), n_div)
    quot = g.op("Div", csf, denom)
    if n_peaks > k:  # more ranks than candidate bins: the rest are the mean of all
        total = _slice(g, csf, k - 1, k, 2)
        rest = g.op("Mul", g.op("Div", total, n_div), _d(g, float(n_peaks - k)))
        quot = g.op("Concat", quot, rest, axis=2)
    num = g.op("ReduceSum", quot, _axes(g, 1, 2), keepdims=0)
    den = g.op(
        "ReduceSum", g.op("Min", n_valid, _d(g, 1.0)), _axes(g, 1, 2), keepdims=0
    )
    return g.op("Div", num, den, stem="f_d")


def _topk(g: GraphBuilder, values: str, k: int) -> tuple[str, str]:
    top, idx = g._fresh("top"), g._fresh("top_idx")
    g.nodes.append(
        helper.make_node(
            "TopK",
            [values, g.const([k], np.int64)],
            [top, idx],
            axis=-1,
            largest=1,
            sorted=1,
        )
    )
    return top, idx


def speed_table(
    est: StickSlipSpeed, rel_tol: float = 1e-7
) -> tuple[FloatArray, FloatArray, float]:
    """The exact form's speed table: frequencies (Hz), speeds (mm/s) and its error.

    Equally spaced from the lowest DFT bin (``rate_hz / nfft``, the lowest ``f_d``) to
    the largest ``f_max`` (the highest ``f_d``), or just below saturation; speeds from
    :meth:`StickSlipSpeed.speed_from_frequency` (the batch bisection). The size doubles
    from :data:`TABLE_MIN` until linear interpolation at the midpoints is within
    ``rel_tol`` of the bisection (at most :data:`TABLE_MAX` entries: an ``f_max``
    range reaching saturation, where the speed grows as ``(f_sat - f)^(-1/3)``, stops
    there with a larger error, recorded in the graph's ``features``).

    Returns
    -------
    f : ndarray (n,)
    v : ndarray (n,)
    err : float
        Largest relative interpolation error at the midpoints.
    """
    f_lo = float(est.rate_hz) / (int(est.window) * int(est.pad_factor))
    f_hi = float(f_max_values(tuple(est.f_max_range), float(est.f_max_step))[-1])
    if est.interpolate:  # a peak's frequency moves up to half a bin either way
        f_lo, f_hi = 0.5 * f_lo, f_hi + 0.5 * f_lo
    f_hi = min(f_hi, float(est.saturation_hz_) * (1.0 - 1e-9))
    n = TABLE_MIN
    while True:
        f = np.linspace(f_lo, f_hi, n)
        v = est.speed_from_frequency(f)
        mid = 0.5 * (f[1:] + f[:-1])
        ref = est.speed_from_frequency(mid)
        err = float(np.max(np.abs(0.5 * (v[1:] + v[:-1]) - ref) / ref))
        if err <= rel_tol or n >= TABLE_MAX:
            return f, v, err
        n *= 2


#: Smallest and largest speed table (:func:`speed_table`).
TABLE_MIN, TABLE_MAX = 4096, 1 << 16
#: Relative interpolation error the speed table is built for.
TABLE_REL_TOL = 1e-7


def _speed(g: GraphBuilder, f: str, est: StickSlipSpeed) -> tuple[str, dict[str, Any]]:
    """Nodes computing the speed (mm/s, NaN when undefined) from ``f`` (Hz), and a note."""
    if est.form == "paper":
        # v = c / (1 / f - pi / w0): closed form, needs f < w0 / pi (NaN compares False)
        rest = g.op("Sub", g.op("Reciprocal", f), _d(g, math.pi / float(est.w0_)))
        v = g.op("Div", _d(g, 1e3 * float(est.stick_length_m_)), rest)
        ok = g.op("Greater", rest, _d(g, 0.0))
        return g.op("Where", ok, v, _d(g, math.nan), stem="speed"), {
            "speed": "closed form"
        }
    # exact form: a table of the batch bisection, linear interpolation (speed_table)
    ft, vt, err = speed_table(est, TABLE_REL_TOL)
    f0, df, n = float(ft[0]), float(ft[1] - ft[0]), len(ft)
    isnan = g.op("IsNaN", f)
    u = g.op(
        "Div", g.op("Sub", g.op("Where", isnan, _d(g, f0), f), _d(g, f0)), _d(g, df)
    )
    u = g.op("Clip", u, _d(g, 0.0), _d(g, n - 1.0))  # f_d lies in the table's range
    i0 = g.op("Floor", g.op("Min", u, _d(g, n - 2.0)))
    idx = g.op("Cast", i0, to=int(onnx.TensorProto.INT64))
    base = g.op("Gather", _d(g, vt[:-1]), idx, axis=0)
    slope = g.op("Gather", _d(g, np.diff(vt)), idx, axis=0)
    v = g.op("Add", base, g.op("Mul", slope, g.op("Sub", u, i0)))
    bad = isnan
    if float(est.saturation_hz_) <= float(ft[-1]) / (1.0 - 1e-9) * (1.0 + 1e-12) or (
        f_max_values(tuple(est.f_max_range), float(est.f_max_step))[-1]
        >= est.saturation_hz_
    ):
        bad = g.op(
            "Or", bad, g.op("GreaterOrEqual", f, _d(g, float(est.saturation_hz_)))
        )
    note = {"speed": "table", "table_size": n, "table_rel_err": err}
    return g.op("Where", bad, _d(g, math.nan), v, stem="speed"), note


def export_stick_slip_speed(
    estimator: StickSlipSpeed,
    *,
    quantity: str = "speed",
    threshold: float | None = None,
    dft_dtype: str = "float32",
    incremental: bool = False,
    opset: int = DEFAULT_OPSET,
) -> DetectorGraph:
    """Export a fitted :class:`StickSlipSpeed` over a window of ``window`` nib samples.

    Parameters
    ----------
    estimator : StickSlipSpeed
        Fitted (``stick_length_m_``, ``w0_``).
    quantity : {"speed", "frequency"}
        Score: the speed (mm/s, :meth:`StickSlipSpeed.predict`) or the dominant
        frequency ``f_d`` (Hz, :meth:`StickSlipSpeed.frequency`).
    threshold : float or None
        Slip decision ``score >= threshold`` (mm/s or Hz); the graph then has classes
        ``("0", "1")``. None: a regression graph without decision.
    dft_dtype : {"float32", "float64"}
        Precision of the two DFT products (module docstring, step 2); with
        ``incremental``, of the peak search on the power spectrum.
    incremental : bool
        Steps 1-2 (detrend, Hamming, DFT) as the runtime op ``sliding_spectrum``
        (:mod:`slipkit.runtime.sliding_spectrum`: the spectrum updated per hop
        from the previous one), the graph reading its power spectrum ``(batch,
        nfft / 2 + 1)`` (module docstring, *Incremental*). Needs the detrend's
        range boundaries on the hop grid (:func:`incremental_problem`).
    opset : int
        Default-domain opset (17 or 18).

    Returns
    -------
    DetectorGraph
        Input ``(batch, window, 1)`` nib samples, oldest first (incremental: the
        power spectrum, with the ``sliding_spectrum`` step in ``preprocessing``);
        ``score`` ``(batch,)``
        float32, :data:`~slipkit.export.detectors.NO_SCORE` where the estimator gives
        NaN; ``hop`` the estimator's, ``first_decision = window - 1``.
    """
    if not isinstance(estimator, StickSlipSpeed):
        # e.g. the learned slipkit.models.spectral regressor: its graph is not eq. 3's
        raise ExportError(
            f"no ONNX graph for a {type(estimator).__name__} speed estimator: only "
            "StickSlipSpeed (eq. 3 inverted) exports"
        )
    check_is_fitted(estimator, "stick_length_m_")
    if estimator.normal_force != "value":
        raise ExportError(
            "StickSlipSpeed export: normal_force='input' (a second, force column) has "
            "no graph yet; export an estimator with normal_force='value'"
        )
    if quantity not in QUANTITIES:
        raise ExportError(f"quantity must be one of {QUANTITIES}; got {quantity!r}")
    if dft_dtype not in ("float32", "float64"):
        raise ExportError(
            f"dft_dtype must be 'float32' or 'float64'; got {dft_dtype!r}"
        )
    w = int(estimator.window)
    g = GraphBuilder(f"stick_slip_{quantity}", opset)
    steps: tuple[dict[str, Any], ...] = ()
    if incremental:
        why = incremental_problem(estimator)
        if why is not None:
            raise ExportError(f"StickSlipSpeed incremental export: {why}")
        nb = w * int(estimator.pad_factor) // 2 + 1
        steps = (sliding_spectrum_step(estimator),)
        inp = helper.make_tensor_value_info(WINDOW_INPUT, FLOAT, ["batch", nb])
        dt = np.float32 if dft_dtype == "float32" else np.float64
        power = (
            WINDOW_INPUT if dt is np.float32 else g.op("Cast", WINDOW_INPUT, to=DOUBLE)
        )
        value = _peak_frequency(g, power, np.arange(nb), nb, estimator, dt)
    else:
        inp = helper.make_tensor_value_info(WINDOW_INPUT, FLOAT, ["batch", w, 1])
        x = g.op(
            "Reshape",
            g.op("Cast", WINDOW_INPUT, to=DOUBLE),
            g.const([-1, w], np.int64),
            stem="x",
        )
        value = _frequency(g, x, estimator, dft_dtype)
    note: dict[str, Any] = {}
    if quantity == "speed":
        value, note = _speed(g, value, estimator)
    # NaN (no estimate) -> NO_SCORE; clip so a huge speed stays a finite float32
    score64 = g.op(
        "Where",
        g.op("IsNaN", value),
        _d(g, NO_SCORE),
        g.op("Clip", value, _d(g, NO_SCORE), _d(g, _F32_MAX)),
    )
    g.nodes.append(helper.make_node("Cast", [score64], [SCORE], to=FLOAT))
    unit = "mm/s" if quantity == "speed" else "Hz"
    lo, hi = (float(v) for v in estimator.f_max_range)
    model = g.build(
        [inp],
        [helper.make_tensor_value_info(SCORE, FLOAT, ["batch"])],
        doc=(
            f"StickSlipSpeed: {quantity} ({unit}) of the last {w} nib samples (eqs. 6-7, "
            f"f_max {lo:g}-{hi:g} Hz, eq. 3 {estimator.form} form)"
        ),
    )
    meaning = (
        f"StickSlipSpeed {'predict' if quantity == 'speed' else 'frequency'} at the "
        f"window's last sample ({unit}); NO_SCORE where undefined"
    )
    if threshold is not None:
        meaning += f"; slip ('1') where score >= {float(threshold):g} {unit}"
    import scipy

    return DetectorGraph(
        model=model,
        input_name=WINDOW_INPUT,
        input_shape=("batch", w, 1) if not incremental else ("batch", nb),
        output_names=(SCORE,),
        score_output=SCORE,
        score_meaning=meaning,
        score_method="decision_function" if threshold is not None else "predict",
        opset=g.opset,
        classes=None if threshold is None else ("0", "1"),
        threshold=None if threshold is None else float(threshold),
        input_meaning=(
            f"the last {w} nib samples at {float(estimator.rate_hz):g} Hz, oldest first"
            if not incremental
            else f"the power spectrum (bins 0..{nb - 1}) of the detrended, Hamming-"
            f"weighted last {w} nib samples (runtime op sliding_spectrum)"
        ),
        features={
            "kind": "detector_window",
            "detector": type(estimator).__name__,
            "quantity": quantity,
            "unit": unit,
            "form": str(estimator.form),
            "nfft": w * int(estimator.pad_factor),
            "harmonics": str(estimator.harmonics),
            "interpolate": bool(estimator.interpolate),
            "dft_factors": list(_factor(w * int(estimator.pad_factor))),
            "dft_dtype": dft_dtype,
            "incremental": bool(incremental),
            "min_peak_to_mean": float(
                getattr(estimator, "min_peak_to_mean", 0.0) or 0.0
            ),
            **note,
            "stick_length_m": float(estimator.stick_length_m_),
            "saturation_hz": float(estimator.saturation_hz_),
        },
        producers=producers(scipy=scipy.__version__),
        window=w,
        hop=int(estimator.hop),
        first_decision=w - 1,
        strict=False,
        preprocessing=steps,
    )


def incremental_problem(estimator: StickSlipSpeed) -> str | None:
    """Why ``estimator`` has no incremental export (None when it has one)."""
    from slipkit.runtime.sliding_spectrum import check_sliding_grid

    return check_sliding_grid(
        int(estimator.window), int(estimator.detrend_frames), int(estimator.hop)
    )


def sliding_spectrum_step(estimator: StickSlipSpeed) -> dict[str, Any]:
    """The runtime step computing ``estimator``'s power spectrum per hop (``sliding_spectrum``)."""
    return {
        "op": "sliding_spectrum",
        "detrend_frames": int(estimator.detrend_frames),
        "hop": int(estimator.hop),
        "nfft": int(estimator.window) * int(estimator.pad_factor),
    }


def graph_speeds(out: ArrayLike) -> FloatArray:
    """The speed graph's score as float64 with :data:`NO_SCORE` read back as NaN."""
    s = np.asarray(out, dtype=np.float64).reshape(-1)
    return np.where(s <= NO_SCORE, np.nan, s)


# -- the decision: a speed threshold --------------------------------------------------
class SpeedSlipDetector(ClassifierMixin, BaseEstimator):
    """Slip where the SlipTack speed estimate reaches a threshold (mm/s).

    Wraps a fitted :class:`StickSlipSpeed` so that the speed has a decision rule:
    ``decision_function`` is the speed (mm/s) per sample, ``-inf`` where undefined
    (warm-up, no peak, saturation), and a sample is slip (``1``) where it is ``>=
    threshold``, as every :class:`~slipkit.baselines.base.StreamDetector`.

    Parameters
    ----------
    speed : StickSlipSpeed
        A fitted speed estimator.
    threshold : float
        Speed (mm/s) at and above which the object slips; 0: whenever a stick-slip
        frequency is found.

    Attributes
    ----------
    threshold_ : float
        ``threshold`` (mm/s).
    classes_ : ndarray
        ``[0, 1]`` (no slip, slip).
    """

    _parameter_constraints: ClassVar[dict[str, list[Any]]] = {
        "speed": [HasMethods(["predict", "frequency"])],
        "threshold": [Interval(Real, 0, None, closed="left")],
    }

    def __init__(self, *, speed: StickSlipSpeed, threshold: float = 0.0) -> None:
        self.speed = speed
        self.threshold = threshold

    def fit(
        self, X: ArrayLike | None = None, y: ArrayLike | None = None
    ) -> SpeedSlipDetector:
        """Check the wrapped estimator is fitted and fix the threshold (no data used)."""
        self._validate_params()
        check_is_fitted(self.speed, "stick_length_m_")
        self.threshold_ = float(self.threshold)
        self.classes_ = np.array([0, 1])
        return self

    def decision_function(
        self, X: ArrayLike, *, segments: ArrayLike | None = None
    ) -> FloatArray:
        """Speed per sample (mm/s) of recordings ``X`` (n_samples, 1); ``-inf`` where undefined."""
        check_is_fitted(self, "threshold_")
        v = self.speed.predict(X, segments=segments)
        return np.where(np.isfinite(v), v, -np.inf)

    def predict(
        self, X: ArrayLike, *, segments: ArrayLike | None = None
    ) -> NDArray[np.int_]:
        """1 (slip) where the speed is ``>= threshold_``, else 0."""
        return (self.decision_function(X, segments=segments) >= self.threshold_).astype(
            int
        )


def export_speed_slip_detector(
    detector: SpeedSlipDetector,
    *,
    dft_dtype: str = "float32",
    incremental: bool = False,
    opset: int = DEFAULT_OPSET,
) -> DetectorGraph:
    """Export a fitted :class:`SpeedSlipDetector`: the speed graph with its threshold."""
    check_is_fitted(detector, "threshold_")
    return export_stick_slip_speed(
        detector.speed,
        threshold=detector.threshold_,
        dft_dtype=dft_dtype,
        incremental=incremental,
        opset=opset,
    )


def main() -> None:
    """Print parity and per-call time of the speed graph on simulated recordings.

    ``python -m slipkit.export.sliptack [key=value ...]``: the ``sliptack_frequency``
    detector config (each ``key=value`` overrides ``detector.key``)
    (physics stick length, friction 0.55 / 0.45), 12 ``sliptack_pull`` trials (seed 1);
    per ``dft_dtype``: speed parity at the runtime's call instants (relative |diff|
    where both are defined, calls where only one is) and decision agreement at 0 and
    30 mm/s; time = median and p99 of 2000 batch-1 onnxruntime calls (one thread).
    """
    import sys
    import time

    from hydra import compose, initialize_config_dir
    from hydra.core.global_hydra import GlobalHydra
    from hydra.utils import instantiate

    from slipkit import config_dir
    from slipkit.export.detectors import (
        _simulate,
        check_detector_parity,
        detector_windows,
    )
    from slipkit.export.parity import onnx_session

    # extra arguments override the detector config, e.g. ``interpolate=false``
    extra = [f"detector.{arg}" for arg in sys.argv[1:]]
    with initialize_config_dir(config_dir=str(config_dir()), version_base="1.3"):
        cfg = compose(
            config_name="train", overrides=["experiment=sliptack_speed", *extra]
        )
    GlobalHydra.instance().clear()
    est = instantiate(cfg.detector).fit(np.zeros((1, 1)), np.full(1, np.nan))
    ds = _simulate("sliptack_pull", 12, 1)
    xs = [
        tr.streams["nib"]["deflection"].to_numpy(dtype=np.float64)[:, None] for tr in ds
    ]
    X = np.concatenate(xs)
    seg = np.concatenate([np.full(len(x), k) for k, x in enumerate(xs)])
    ref_all = est.predict(X, segments=seg)
    print(
        f"{'dft_dtype':9s} {'W':>5s} {'hop':>3s} {'calls':>6s} {'max rel':>9s} "
        f"{'NaN mism':>8s} {'agree@0':>8s} {'agree@30':>8s} {'us p50':>7s} {'us p99':>7s}"
    )
    for dtype in ("float32", "float64"):
        graph = export_stick_slip_speed(est, dft_dtype=dtype)
        sess = onnx_session(graph)
        refs, ours = [], []
        for k, x in enumerate(xs):
            windows, inst = detector_windows(graph, x)
            out = sess.run([graph.score_output], {graph.input_name: windows})[0]
            ours.append(graph_speeds(out))
            refs.append(ref_all[seg == k][inst])
        ref, mine = np.concatenate(refs), np.concatenate(ours)
        both = np.isfinite(ref) & np.isfinite(mine)
        rel = np.abs(ref[both] - mine[both]) / np.abs(ref[both])
        agree = []
        for thr in (0.0, 30.0):
            det = SpeedSlipDetector(speed=est, threshold=thr).fit()
            rep = check_detector_parity(
                det, export_speed_slip_detector(det, dft_dtype=dtype), X, segments=seg
            )
            agree.append(100 * rep["agreement"])
        w1 = windows[:1]
        times = []
        for j in range(2000):
            w1 = windows[j % len(windows)][None]
            t0 = time.perf_counter_ns()
            sess.run([graph.score_output], {graph.input_name: w1})
            times.append(time.perf_counter_ns() - t0)
        print(
            f"{dtype:9s} {graph.window:5d} {graph.hop:3d} {len(ref):6d} "
            f"{float(rel.max()) if rel.size else 0.0:9.2e} "
            f"{int(np.sum(np.isfinite(ref) != np.isfinite(mine))):8d} {agree[0]:8.3f} "
            f"{agree[1]:8.3f} {np.median(times) / 1e3:7.1f} "
            f"{np.percentile(times, 99) / 1e3:7.1f}"
        )


# ``python -m slipkit.export.sliptack`` runs a second copy of this module as __main__;
# only the imported module registers (a duplicate registration raises).
if __name__ != "__main__":
    register_exporter(StickSlipSpeed, export_stick_slip_speed)
    register_exporter(SpeedSlipDetector, export_speed_slip_detector)

__all__ = [
    "QUANTITIES",
    "SpeedSlipDetector",
    "dft_matrices",
    "export_speed_slip_detector",
    "export_stick_slip_speed",
    "graph_speeds",
    "incremental_problem",
    "sliding_spectrum_step",
    "speed_table",
]

if __name__ == "__main__":
    main()
