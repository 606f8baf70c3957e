"""Exporter of the SlipTack stick-slip speed estimator: a window of nib samples in, speed out.

:class:`~slipkit.families.sliptack.speed.StickSlipSpeed` is analytic and every step of it
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
   of :mod:`slipkit.families.sliptack.export.spectral` is ~3 us faster here but rounds the twiddled
   values to float32 once more: speeds then differ from the batch by up to 1.5e-6
   relative, over the tests' 1e-6.)
   ONNX's ``DFT`` op is not used (onnxruntime 1.31 runs lengths that are not powers of
   two as an ``O(n^2)`` loop). The two products run in ``dft_dtype`` (float32 by
   default: MLAS's float32 kernels, ~14 us per call less than float64 in
   ``python -m slipkit.families.sliptack.export.parity``; the power spectrum is then good to ~1e-6
   relative, far below the gaps between the peaks the rule compares);
3. **peaks** (eqs. 6-7): strict local maxima of the power spectrum below the largest
   ``f_max``, the ``min_peak_ratio`` rule (squared, on power) against the largest bin of
   the whole spectrum (DC excluded) and the gate, as one ``Greater`` of each bin against
   ``Max(lower, upper, threshold)`` (the ratio times ``1 - eps``, so ``>=`` becomes
   ``>``; a failed gate makes the threshold ``+inf``); the harmonic rule as one
   ``MatMul`` + ``Less``. The counted peaks are sorted once by power (one ``TopK`` of
   ``(c + 1) // 2``; ties: the lower bin, as the batch sort), their rank among the
   peaks at or below each ``f_max`` is one ``CumSum`` of a constant eligibility table
   gathered in sorted order, and eq. 6's "mean over ``j = 1..n_peaks`` of the top-``j``
   means" is a fixed weighted sum of the top ``L = min(count, n_peaks)`` values
   (:func:`peak_ranks`): two ``MatMul`` products and lookups by ``L`` per ``f_max``, no
   ``TopK`` per ``f_max`` row. ``f_d`` is the mean over the ``f_max`` values with a
   peak (``f_max`` values between the same two bins share one column, weighted by
   their number). The interpolation is one log-parabola per candidate bin (one
   ``(2, 3)`` ``MatMul`` for the vertex offset's numerator and denominator; a
   zero-power neighbour of a peak, never seen in noisy data, gets a clipped offset
   where the batch form's is 0);
4. **speed** (eq. 3 inverted): ``form="paper"`` in closed form; ``form="exact"`` by
   linear interpolation in a table of the batch bisection over the frequencies ``f_d``
   can take (:func:`speed_table`: from the DFT resolution to the largest ``f_max``,
   16384 entries for the default detector, within 1e-7 relative of the bisection),
   whose row coordinate is folded into the per-bin frequencies (:func:`_speed_index`):
   one ``Cast`` and two ``Gather`` nodes. An unrolled bisection or Newton iteration is
   exact too but costs ~8 graph nodes per step.

A window holding NaN / inf makes every DFT bin NaN and a constant window every bin 0:
no bin is then a strict local maximum, eq. 6-7's sum and count are 0, and the graph
scores :data:`~slipkit.export.detectors.NO_SCORE` (the batch estimator's NaN; also
for no spectral peak and a frequency at or above saturation; read back as NaN by
:func:`graph_speeds`). Known differences from the batch estimator: ``find_peaks``
reports the middle of a flat-topped peak where the graph needs a strict maximum (equal
magnitudes in neighbouring bins do not occur in noisy signals), a float64 recording
that varies by less than float32 resolution is constant for the graph (NaN) but not
always for the batch form, and with the ``f_max`` range reaching saturation a
frequency within 1e-9 relative below it has no score (the table's last row).

Cost (figures in docs/deploy.md, ``benchmarks/bench_deploy.py --only
sliptack``): at batch 1 a small node costs its dispatch and a large one its
arithmetic; the per-``f_max`` ``TopK`` over ``(n_fmax, c)`` was the largest node
(and grows with the number of peaks); the shipped detector config's graph has 73
nodes (84 before).

Prepared spectrum (``prepare=True``, the export default through ``slipkit export``'s
``regression.prepare``). Steps 1-2 are linear in the samples, so the DFT of a
decision's window is the DFT of the same window with its newest sample replaced by the
one before it, plus ``(x[W - 1] - x[W - 2])`` times a constant column
(:func:`last_sample_column`). The export then writes two graphs: a *prepare* graph
(:func:`_prepare_graph`, 20 nodes: steps 1-2 on ``[x[1:], x[-1]]`` of the window the
runtime holds one frame before the decision) whose output :data:`PARTIAL` the runtime
feeds to the main graph, which adds the newest sample's share (five nodes) and runs
steps 3-4. :class:`~slipkit.runtime.StreamLoop` runs the prepare graph on the frame
before each decision (manifest ``prepare``, :mod:`slipkit.runtime.bundle`), a frame
that otherwise only stores its sample; the decision frame's latency holds the main
graph alone (62 nodes instead of 73). The difference is rounded once in float32
(``6e-8`` of itself, not of the samples' offset) and the prepared DFT is float32 as the
whole-window graph's: speeds agree with the whole-window graph's within ``1e-6``
relative. A constant window stays exactly 0 (the prepared window is constant and the
difference 0).

Decision. A speed has no slip class; :class:`SpeedSlipDetector` wraps a fitted
estimator with a speed threshold (mm/s): slip (``1``) where ``speed >= threshold``,
no slip where the speed is below it or undefined. Threshold 0 reads "a stick-slip
frequency is present". The wrapper is what ``slipkit export`` deploys
(:mod:`slipkit.export.deploy`, task ``SlipTackSpeed``) and what parity compares with
(:func:`slipkit.export.detectors.check_detector_parity`; the graph's ``window`` /
``hop`` / ``first_decision`` are ``W`` / the estimator's ``hop`` / ``W - 1``, the
batch estimator's estimation instants).

``python -m slipkit.families.sliptack.export.parity`` prints parity and the time per call on simulated
``sliptack_pull`` recordings.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import onnx
from numpy.typing import ArrayLike, NDArray
from onnx import helper
from sklearn.utils.validation import check_is_fitted

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
from slipkit.families.sliptack.speed import (
    StickSlipSpeed,
    f_max_values,
    gate_first_bin,
    harmonic_relation,
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


def _spectrum(
    g: GraphBuilder, x: str, est: StickSlipSpeed, dft_dtype: str, rank: int
) -> str:
    """Nodes from the windows ``x`` (float64, ``(b, W)`` or, ``rank`` 3, ``(b, W, 1)``)
    to the power spectrum ``(b, 1, N1 K2)`` in ``dft_dtype``, bin ``k1 + N1 k2`` at
    ``k1 K2 + k2`` (steps 1-2 of the module docstring; a ``(b, W, 1)`` input needs no
    reshape to ``(b, W)``, and the product's layout gives the power in one
    ``ReduceSumSquare`` without a reshape after it).
    """
    return _power(g, _dft(g, _windowed(g, x, est, rank), est, dft_dtype, rank))


def _windowed(g: GraphBuilder, x: str, est: StickSlipSpeed, rank: int) -> str:
    """Step 1 (detrend) and the Hamming weights: ``(b, W[, 1])`` float64 in and out."""
    w = int(est.window)
    s = min(int(est.detrend_frames), w)
    i64 = np.int64
    # the residual is invariant to a constant shift; subtracting the first sample
    # (exact in float64 for float32 samples) keeps the cumulative sums small and makes
    # a constant window exactly 0
    xc = g.op("Sub", x, _slice(g, x, 0, 1, 1), stem="xc")
    left = s // 2  # uniform_filter1d's centre, for odd and even sizes
    # edge padding, one extra sample on the right so the exclusive cumsum has W + s values
    tail = [0] if rank == 3 else []
    pads = g.const([0, left, *tail, 0, s - left, *tail], i64)
    padded = g.op("Pad", xc, pads, mode="edge", stem="padded")
    cs = g.op("CumSum", padded, g.const(1, i64), exclusive=1, stem="cs")
    diff = g.op("Sub", _slice(g, cs, s, s + w, 1), _slice(g, cs, 0, w, 1))
    # h (xc - diff / s): the Hamming weights and 1 / s as two constant Muls
    shape = (w, 1) if rank == 3 else (w,)
    h = np.hamming(w)
    return g.op(
        "Sub",
        g.op("Mul", xc, _d(g, h.reshape(shape))),
        g.op("Mul", diff, _d(g, (h / s).reshape(shape))),
        stem="windowed",
    )


def _dft(
    g: GraphBuilder, xw: str, est: StickSlipSpeed, dft_dtype: str, rank: int
) -> str:
    """Step 2's two products: the windowed samples ``xw`` (float64, ``(b, W[, 1])``) to
    the DFT ``(b, N1, 1, 2 K2)`` in ``dft_dtype`` (re and im interleaved per ``k2``)."""
    w = int(est.window)
    nfft = w * int(est.pad_factor)
    i64 = np.int64
    tail = [0] if rank == 3 else []
    if nfft > w:
        pad = [0, 0, *tail, 0, nfft - w, *tail]
        xw = g.op("Pad", xw, g.const(pad, i64), stem="zero_padded")
    f1i, gi, n1, n2 = _dft_constants(nfft)
    dt = np.float32 if dft_dtype == "float32" else np.float64
    if dt is np.float32:
        xw = g.op("Cast", xw, to=FLOAT)
    grid = g.op("Reshape", xw, g.const([-1, n1, n2], i64), stem="grid")
    a = g.op("MatMul", g.const(f1i, dt), grid, stem="stage1")  # (b, 2 N1, N2)
    a = g.op("Reshape", a, g.const([-1, n1, 1, 2 * n2], i64))
    return g.op("MatMul", a, g.const(gi, dt), stem="stage2")  # (b, N1, 1, 2 K2)


def _dft_constants(nfft: int) -> tuple[FloatArray, FloatArray, int, int]:
    """:func:`dft_matrices` in the layout :func:`_dft` multiplies by: ``F1`` with its
    rows interleaved per ``k1`` (cos row, then -sin row), so that stage 1's output
    reshapes to ``(b, N1, 1, 2 N2)`` (``[A_re, A_im]`` of each ``k1`` as one row, and
    stage 2 is ``N1`` products of one ``2 N2`` row by ``G[k1]``), and ``G``'s columns
    interleaving re and im per ``k2`` (the product reshapes to ``(b, 1, N1 K2, 2)``,
    one ``ReduceSumSquare`` from the power). Returns ``(F1, G, N1, N2)``."""
    f1, gm, n1, k2n = dft_matrices(nfft)
    n2 = nfft // n1
    f1i = f1.reshape(2, n1, n1).transpose(1, 0, 2).reshape(2 * n1, n1)
    gi = gm.reshape(n1, 2 * n2, 2, k2n).transpose(0, 1, 3, 2).reshape(n1, 2 * n2, -1)
    return f1i, gi, n1, n2


def _power(g: GraphBuilder, y: str) -> str:
    """The DFT ``y`` ``(b, N1, 1, 2 K2)`` to its power ``(b, 1, N1 K2)`` (same dtype)."""
    i64 = np.int64
    y = g.op("Reshape", y, g.const([0, 1, -1, 2], i64))
    return _reduce(g, "ReduceSumSquare", y, (3,), 0)  # (b, 1, N1 K2)


def last_sample_column(est: StickSlipSpeed) -> FloatArray:
    """What the window's newest sample adds to :func:`_dft`'s output, per unit.

    Steps 1-2 are linear in the samples: the DFT of a window is that of the same
    window with its newest sample replaced by the one before it, plus ``(x[W - 1] -
    x[W - 2])`` times this column (the steps applied, in float64, to the unit vector
    of the last sample: :func:`scipy.ndimage.uniform_filter1d` as the batch
    estimator's detrend, then the Hamming weights and the DFT in :func:`_dft`'s
    layout). Returns shape ``(N1 2 K2,)``.
    """
    from scipy.ndimage import uniform_filter1d

    w = int(est.window)
    nfft = w * int(est.pad_factor)
    s = min(int(est.detrend_frames), w)
    e = np.zeros(w)
    e[-1] = 1.0
    xw = np.zeros(nfft)
    xw[:w] = np.hamming(w) * (e - uniform_filter1d(e, s, mode="nearest"))
    f1i, gi, n1, n2 = _dft_constants(nfft)
    a = (f1i @ xw.reshape(n1, n2)).reshape(n1, 1, 2 * n2)
    return np.asarray(a @ gi, dtype=np.float64).reshape(-1)


def _bin_positions(nfft: int) -> NDArray[np.intp]:
    """``pos[k]``: where DFT bin ``k`` (0 .. nfft / 2) sits in :func:`_spectrum`'s output."""
    n1, k2n = _dims(nfft)
    ks = (np.arange(n1)[:, None] + n1 * np.arange(k2n)[None, :]).reshape(-1)
    return np.argsort(ks)[: nfft // 2 + 1]


def _dims(nfft: int) -> tuple[int, int]:
    """``(N1, K2)`` of :func:`dft_matrices` without building the matrices."""
    n1, _ = _factor(int(nfft))
    return n1, (int(nfft) // 2) // n1 + 1


def _frequency(g: GraphBuilder, x: str, est: StickSlipSpeed, dft_dtype: str) -> str:
    """Nodes computing ``f_d`` (Hz, float64, NaN when undefined) of the windows ``x`` (b, W).

    (:mod:`slipkit.families.sliptack.export.spectral`'s entry: the speed graph itself uses
    :func:`_spectrum` and :func:`_peak_value` without the NaN.)
    """
    nfft = int(est.window) * int(est.pad_factor)
    power = _spectrum(g, x, est, dft_dtype, rank=2)
    dt = np.float32 if dft_dtype == "float32" else np.float64
    n1, k2n = _dims(nfft)
    f = _peak_value(g, power, _bin_positions(nfft), n1 * k2n, est, dt)
    return g.op("Where", g.op("Greater", f, _d(g, 0.0)), f, _d(g, math.nan))


def _peak_frequency(
    g: GraphBuilder,
    power: str,
    pos: NDArray[np.intp],
    n_power: int,
    est: StickSlipSpeed,
    dt: type[np.floating[Any]],
) -> str:
    """Nodes from the power spectrum ``power`` (b, n_power) to ``f_d`` (Hz, float64, NaN).

    ``pos[k]`` is where DFT bin ``k`` (0 .. nfft / 2) sits along ``power``'s axis 1
    (:func:`_peak_value` with a NaN where it gives 0).
    """
    p3 = g.op("Reshape", power, g.const([-1, 1, n_power], np.int64))
    f = _peak_value(g, p3, pos, n_power, est, dt)
    return g.op("Where", g.op("Greater", f, _d(g, 0.0)), f, _d(g, math.nan))


def _peak_value(
    g: GraphBuilder,
    power: str,
    pos: NDArray[np.intp],
    n_power: int,
    est: StickSlipSpeed,
    dt: type[np.floating[Any]],
    scale: float = 1.0,
    shift: float = 0.0,
) -> str:
    """Nodes from the power spectrum ``power`` (b, 1, n_power) to ``scale f_d + shift``
    (float64, ``(b,)``), exactly 0 where ``f_d`` is undefined.

    ``pos[k]`` is where DFT bin ``k`` (0 .. nfft / 2) sits along ``power``'s axis 2;
    other entries are ignored. Steps 3 (peaks, eqs. 6-7) and the gate of the module
    docstring. ``scale`` and ``shift`` (the speed table's index, :func:`_speed`) are
    folded into the per-bin frequencies: eq. 6-7's weights of an ``f_max`` with a peak
    sum to 1, so the weighted mean of ``scale q + shift`` is ``scale f + shift``; an
    ``f_max`` without a peak adds 0 to the sum and to the count, and with no peak at
    all the sum is 0 (the count is clamped to 1 x n_peaks).

    Cost: the per-``f_max`` ``TopK`` over ``(n_fmax, c)`` was the largest
    node of the graph (~15 us of ~75 at batch 1, more on spectra with many peaks); the
    peaks are sorted once now, and the ranks per ``f_max`` are one ``CumSum`` over
    ``(K, n_sets)``, ``K = (c + 1) // 2``, with the weights of :func:`peak_ranks`.
    """
    rate = float(est.rate_hz)
    nfft = int(est.window) * int(est.pad_factor)
    last = nfft // 2
    i64 = np.int64
    # 3. peaks: interior bins 1..c with freq <= the largest f_max (find_peaks skips the ends)
    freqs = np.fft.rfftfreq(nfft, 1.0 / rate)
    fmax = f_max_values(tuple(est.f_max_range), float(est.f_max_step))
    c = min(int(np.sum(freqs <= fmax[-1])) - 1, last - 1)
    if c < 1:
        raise ExportError(
            f"StickSlipSpeed export: no DFT bin between 0 Hz and f_max {fmax[-1]:g} Hz "
            f"(resolution {rate / nfft:g} Hz); widen window or f_max_range"
        )
    # the (bin - 1, bin, bin + 1) powers of bins 1..c in one Gather, split in three
    trip = g.op(
        "Gather",
        power,
        g.const(np.concatenate([pos[d : d + c] for d in (0, 1, 2)]), i64),
        axis=2,
    )  # (b, 1, 3 c)
    lower, mid, upper = (g._fresh(n) for n in ("lower", "mid", "upper"))
    split: dict[str, Any] = {"num_outputs": 3} if g.opset >= 18 else {}
    g.nodes.append(
        helper.make_node("Split", [trip], [lower, mid, upper], axis=2, **split)
    )
    # min_peak_ratio (squared, on power) against the largest bin of the whole spectrum
    # (DC excluded), folded into the mask, times (1 - eps): "mid >= r x max" is then
    # "mid > the float just below r x max", so one Greater against Max(lower, upper,
    # threshold) is the strict local maximum and the ratio rule together (the
    # product's rounding moves the threshold by one ulp, far inside the 1e-6 of the
    # float32 spectrum)
    eps = float(np.finfo(dt).eps) / 2.0
    ratio2 = float(est.min_peak_ratio) ** 2 * (1.0 - eps)
    spectrum = np.isin(np.arange(n_power), pos[1:]) * ratio2
    gate = float(getattr(est, "min_peak_to_mean", 0.0) or 0.0)
    if gate > 0.0:
        # no stick-slip oscillation: the largest bin of the gate band is not gate x
        # the band's mean power (gate_first_bin); then the threshold is +inf, no peak
        # counts, f_d is undefined. Both maxima from one (2, n_power) product.
        k0 = gate_first_bin(nfft, min(int(est.detrend_frames), int(est.window)))
        in_band = np.isin(np.arange(n_power), pos[k0:])
        both = _reduce(
            g,
            "ReduceMax",
            g.op("Mul", power, g.const(np.stack([spectrum, in_band]), dt)),
            (2,),
            1,
        )  # (b, 2, 1)
        gmax_r, bmax = g._fresh("gmax_r"), g._fresh("bmax")
        split = {"num_outputs": 2} if g.opset >= 18 else {}
        g.nodes.append(
            helper.make_node("Split", [both], [gmax_r, bmax], axis=1, **split)
        )
        # gate x the band's mean power: one MatMul with the weights gate / n_band
        mean = g.op(
            "MatMul", power, g.const((in_band * (gate / (last + 1 - k0)))[:, None], dt)
        )
        thr = g.op(
            "Where",
            g.op("GreaterOrEqual", bmax, mean),
            gmax_r,
            g.const(np.inf, dt),
            stem="threshold",
        )
    else:
        thr = _reduce(
            g, "ReduceMax", g.op("Mul", power, g.const(spectrum, dt)), (2,), 1
        )
    peak = g.op(
        "Greater", mid, g.op("Max", lower, upper, thr), stem="peak"
    )  # (b, 1, c)
    if est.harmonics == "fundamental":
        # a counted peak at ~m x a lower counted peak is a harmonic: one MatMul with a
        # constant (c, c) relation of the bins (harmonic_mask's rule on bin numbers)
        # minus 4096 on the diagonal, so that "a peak and no hit" is one Less (in
        # float32: sums of a few 0/1 products and 4096 are exact)
        rel = harmonic_relation(np.arange(1, c + 1), float(est.harmonic_tol))
        big = 4096.0
        hits = g.op(
            "MatMul",
            g.op("Cast", peak, to=FLOAT),
            g.const(rel.astype(np.float32) - big * np.eye(c, dtype=np.float32)),
        )
        peak = g.op("Less", hits, g.const(0.5 - big, np.float32), stem="fundamental")
    # eq. 6-7 without a TopK per f_max: the counted peaks sorted once by power (a
    # counted peak's power, -1 for other bins; at most (c + 1) // 2 strict maxima;
    # ties: the lower bin first, as the batch sort), then per f_max their ranks among
    # the peaks at or below it by one CumSum (peak_ranks)
    score = g.op("Where", peak, mid, g.const(-1.0, dt))
    n_sorted = (c + 1) // 2
    _, order = _topk(g, score, n_sorted)  # (b, 1, K), largest first
    # the per-bin value q (scale x frequency + shift, > 0), 0 for bins not counted
    bin_hz = float(freqs[1] - freqs[0])
    q0 = scale * np.arange(1, c + 1, dtype=np.float64) * bin_hz + shift
    if est.interpolate:
        # the parabola through the log powers (= 2 log magnitudes: the vertex offset is
        # the same) of each bin and its neighbours, as parabolic_offset: their log
        # (powers clamped to the smallest normal float32: a zero bin has a finite log),
        # one constant MatMul (2, 3) for the offset's numerator ``h (a - c)`` and its
        # denominator ``a - 2 b + c`` (h = half a bin, times scale), Clip to +-h. No
        # den < 0 test: a strict maximum has one, and other bins are dropped below.
        logp = g.op("Log", g.op("Max", trip, g.const(np.finfo(np.float32).tiny, dt)))
        if dt is np.float32:
            logp = g.op("Cast", logp, to=DOUBLE)
        logp = g.op("Reshape", logp, g.const([-1, 3, c], i64))
        half = 0.5 * bin_hz * scale
        nd = g.op("MatMul", _d(g, [[half, 0.0, -half], [1.0, -2.0, 1.0]]), logp)
        num, den = g._fresh("num"), g._fresh("den")
        split = {"num_outputs": 2} if g.opset >= 18 else {}
        g.nodes.append(helper.make_node("Split", [nd], [num, den], axis=1, **split))
        off = g.op("Clip", g.op("Div", num, den), _d(g, -half), _d(g, half))
        q = g.op("Add", off, _d(g, q0), stem="peak_value")  # (b, 1, c)
    else:
        q = _d(g, q0)
    # the value of each sorted peak (0: not a counted peak), and 1 where it is one
    qm = g.op("Where", peak, q, _d(g, 0.0))
    qs = g.op("GatherElements", qm, order, axis=2, stem="sorted_value")  # (b, 1, K)
    valid = g.op("Sign", qs)  # (b, 1, K)
    n_peaks = int(est.n_peaks)
    cols, mult, ((alpha_n, has_n)) = peak_ranks(freqs[1 : c + 1], fmax, n_peaks)
    # The (K, n_sets) rank tables in float32 (their ~11 elementwise ops on
    # 4300 values cost 25 us per call in float64, 16 in float32): eligibility, ranks
    # and counts are small whole numbers and H(r) sums of 1 / r (exact or within 6e-8
    # in float32); the values q stay float64 (one float64 product per f_max below).
    f32 = np.float32
    elig = g.op(
        "Gather",
        g.const(cols, f32),
        g.op("Reshape", order, g.const([-1, n_sorted], i64)),
        axis=0,
        stem="eligible",
    )  # (b, K, n_sets): 1 where the i-th largest is at or below the f_max
    rank = g.op("CumSum", elig, g.const(1, i64), stem="rank")
    # the top n_peaks of each f_max: max(0, min(eligible, n_peaks + 1 - rank)) (ranks
    # are whole numbers; Min and Relu cost less than a Where here)
    in_top = g.op(
        "Relu", g.op("Min", elig, g.op("Sub", g.const(n_peaks + 1.0, f32), rank))
    )
    # H(rank - 1) of each eligible peak: the exclusive running sum of 1 / rank (rank
    # is 0 only before the first eligible peak)
    harm = g.op(
        "CumSum",
        g.op("Div", elig, g.op("Max", rank, g.const(1.0, f32))),
        g.const(1, i64),
        exclusive=1,
    )
    # per f_max (b, 1, n_sets): the number L of top values, then each value's weight
    # n x (alpha(L) - beta(r)) = (H_L + n / L - 1) - H(r - 1) (peak_ranks), and the
    # weighted sum of the values in float64
    count = g.op("MatMul", g.op("Cast", valid, to=FLOAT), in_top, stem="count")
    li = g.op("Cast", count, to=int(onnx.TensorProto.INT64))
    alpha = g.op("Gather", g.const(alpha_n, f32), li, axis=0)  # (b, 1, n_sets)
    weight = g.op("Mul", in_top, g.op("Sub", alpha, harm), stem="weight")
    per = g.op("MatMul", qs, g.op("Cast", weight, to=DOUBLE), stem="per")
    has = g.op("Gather", _d(g, has_n), li, axis=0)  # n_peaks where L >= 1
    if np.any(mult > 1):  # f_max values with the same bins below them: one column
        per = g.op("Mul", per, _d(g, mult))
        has = g.op("Mul", has, _d(g, mult))
    num = _reduce(g, "ReduceSum", per, (1, 2), 0)
    den = _reduce(g, "ReduceSum", has, (1, 2), 0)
    return g.op("Div", num, g.op("Max", den, _d(g, float(n_peaks))), stem="f_value")


def peak_ranks(
    bin_hz: ArrayLike, fmax: ArrayLike, n_peaks: int
) -> tuple[FloatArray, FloatArray, tuple[FloatArray, FloatArray]]:
    """Constants of the graph's eq. 6-7: eligibility, multiplicities, weight tables.

    Eq. 6 per ``f_max``: with the ``L = min(count, n_peaks)`` largest peaks at or below
    it, ``q_1 >= ... >= q_L`` by power, "the mean over ``j = 1..n_peaks`` of the top-``j``
    means" (the mean of all ``L`` for ``j > L``) is ``sum_r q_r (alpha(L) - beta(r))``
    with ``n alpha(L) = H_L + n / L - 1`` and ``n beta(r) = H_{r - 1}`` (``H`` the
    harmonic numbers, ``n = n_peaks``; the weights sum to 1). So the graph needs per
    ``f_max`` only the sum of the top values, the sum of ``H_{r - 1} q_r`` (a running
    sum of ``1 / rank``) and ``L``, and per-``f_max`` lookups by ``L``.

    Parameters
    ----------
    bin_hz : array_like (c,)
        Frequencies (Hz) of the candidate bins 1..c.
    fmax : array_like (n_fmax,)
        Eq. 7's ``f_max`` values (Hz).
    n_peaks : int

    Returns
    -------
    cols : ndarray (c, n_sets)
        1 where a bin is at or below an ``f_max``, one column per distinct set of bins
        (``f_max`` values between the same two bins share one).
    mult : ndarray (n_sets,)
        How many ``f_max`` values each column stands for.
    (alpha_n, has_n) : ndarrays (n_peaks + 1,)
        ``n alpha(L)`` and ``n [L >= 1]`` for ``L = 0 .. n_peaks`` (0 at ``L = 0``).
    """
    below = np.asarray(bin_hz, dtype=np.float64)[:, None] <= np.asarray(fmax)[None, :]
    cols, mult = np.unique(below, axis=1, return_counts=True)
    n = int(n_peaks)
    ell = np.arange(1, n + 1, dtype=np.float64)
    alpha_n = np.concatenate([[0.0], np.cumsum(1.0 / ell) + n / ell - 1.0])
    has_n = np.concatenate([[0.0], np.full(n, float(n))])
    return cols.astype(np.float64), mult.astype(np.float64), (alpha_n, has_n)


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


def _speed_index(est: StickSlipSpeed) -> tuple[float, float, dict[str, Any]]:
    """The exact form's table (:func:`speed_table`) as the graph reads it.

    Returns ``scale``, ``shift`` (the row coordinate ``u = scale f + shift`` of a
    frequency ``f`` in Hz: ``u = 2`` at the table's first frequency) and the
    arrays ``a``, ``b`` of the rows (``speed = a[i] + b[i] u`` for ``i = floor(u)``)
    with the table's error, in a dict. Row 0 is "no estimate" (``a = NO_SCORE``,
    ``b = 0``: ``u = 0`` exactly when there is no peak), row 1 extends the first
    segment below the first frequency (rounding), rows ``2 .. n`` are the ``n - 1``
    segments, row ``n + 1`` extends the last one above the table (rounding) or, when
    the ``f_max`` range reaches saturation, is "no estimate" too.
    """
    ft, vt, err = speed_table(est, TABLE_REL_TOL)
    f0, df, n = float(ft[0]), float(ft[1] - ft[0]), len(ft)
    seg = np.clip(np.arange(n + 2) - 2, 0, n - 2)
    slope = np.diff(vt)[seg]
    a = vt[seg] - slope * (seg + 2)
    b = slope.copy()
    a[0], b[0] = NO_SCORE, 0.0
    top = f_max_values(tuple(est.f_max_range), float(est.f_max_step))[-1]
    if est.interpolate:
        top = top + 0.5 * float(est.rate_hz) / (int(est.window) * int(est.pad_factor))
    clip = float(est.saturation_hz_) <= top
    if clip:
        a[-1], b[-1] = NO_SCORE, 0.0
    # else u <= n + 1 up to rounding (f <= the largest f_max + half a bin): no Clip
    note = {"a": a, "b": b, "n": n, "err": err, "clip": clip}
    return 1.0 / df, 2.0 - f0 / df, note


def _speed(
    g: GraphBuilder, u: str, est: StickSlipSpeed, table: dict[str, Any] | None
) -> tuple[str, dict[str, Any]]:
    """Nodes from :func:`_peak_value`'s ``u`` (``(b,)``, 0 without an estimate) to the
    float64 score (mm/s, :data:`NO_SCORE` where undefined), and a note.

    ``form="paper"``: ``u`` is ``f_d`` in Hz and the speed is ``c / (1 / f - pi /
    w0)`` in closed form (``f = 0`` gives 0, not a speed; ``f`` at or above ``w0 /
    pi`` a negative speed: both :data:`NO_SCORE`). ``form="exact"``: ``u`` is the
    table's row coordinate (:func:`_speed_index`) and the speed one ``a + b u`` of
    the row ``floor(u)`` (the cast to int64 truncates, ``u >= 0``).
    """
    if table is None:
        rest = g.op("Sub", g.op("Reciprocal", u), _d(g, math.pi / float(est.w0_)))
        v = g.op("Div", _d(g, 1e3 * float(est.stick_length_m_)), rest)
        v = g.op("Where", g.op("Greater", v, _d(g, 0.0)), v, _d(g, NO_SCORE))
        # a huge speed close below saturation stays a finite float32
        v = g.op("Clip", v, _d(g, NO_SCORE), _d(g, _F32_MAX), stem="speed")
        return v, {"speed": "closed form"}
    n = int(table["n"])
    if table["clip"]:  # frequencies above the table's last row (saturation)
        u = g.op("Clip", u, _d(g, 0.0), _d(g, n + 1.0))
    row = g.op("Cast", u, to=int(onnx.TensorProto.INT64))
    v = g.op(
        "Add",
        g.op("Gather", _d(g, table["a"]), row, axis=0),
        g.op("Mul", g.op("Gather", _d(g, table["b"]), row, axis=0), u),
        stem="speed",
    )
    return v, {"speed": "table", "table_size": n, "table_rel_err": table["err"]}


def export_stick_slip_speed(
    estimator: StickSlipSpeed,
    *,
    quantity: str = "speed",
    threshold: float | None = None,
    dft_dtype: str = "float32",
    incremental: bool = False,
    prepare: bool = False,
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
        (:mod:`slipkit.runtime.ops.sliptack`: the spectrum updated per hop
        from the previous one), the graph reading its power spectrum ``(batch,
        nfft / 2 + 1)`` (module docstring, *Incremental*). Needs the detrend's
        range boundaries on the hop grid (:func:`incremental_problem`).
    prepare : bool
        Split the graph in two (module docstring, *Prepared spectrum*): a
        ``prepare`` graph the runtime runs on the frame before each decision
        (steps 1-2 on the window with its newest sample not yet known) and the
        main graph, which adds the newest sample's share (:func:`last_sample_column`)
        to the prepared DFT and runs steps 3-4. Not with ``incremental``.
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
        # e.g. the learned slipkit.families.sliptack.spectral regressor: its graph is not eq. 3's
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
    dt = np.float32 if dft_dtype == "float32" else np.float64
    scale, shift, table = 1.0, 0.0, None
    if quantity == "speed" and estimator.form != "paper":
        scale, shift, table = _speed_index(estimator)
    if prepare and (incremental or w < 2):
        raise ExportError(
            "StickSlipSpeed export: prepare needs the whole-window graph "
            "(incremental=False) and a window of at least 2 samples"
        )
    prep_model = None
    if incremental:
        why = incremental_problem(estimator)
        if why is not None:
            raise ExportError(f"StickSlipSpeed incremental export: {why}")
        nb = w * int(estimator.pad_factor) // 2 + 1
        steps = (sliding_spectrum_step(estimator),)
        inp = helper.make_tensor_value_info(WINDOW_INPUT, FLOAT, ["batch", nb])
        power = (
            WINDOW_INPUT if dt is np.float32 else g.op("Cast", WINDOW_INPUT, to=DOUBLE)
        )
        power = g.op("Reshape", power, g.const([-1, 1, nb], np.int64))
        value = _peak_value(g, power, np.arange(nb), nb, estimator, dt, scale, shift)
    elif prepare:
        inp = helper.make_tensor_value_info(WINDOW_INPUT, FLOAT, ["batch", w, 1])
        nfft = w * int(estimator.pad_factor)
        n1, k2n = _dims(nfft)
        proto = FLOAT if dt is np.float32 else DOUBLE
        part = helper.make_tensor_value_info(PARTIAL, proto, ["batch", 1, 2 * n1 * k2n])
        # the newest sample's share: (x[W - 1] - x[W - 2]) x its column; the float32
        # difference is rounded once (relative 6e-8 of itself), where a product of
        # each sample by the column would lose the difference to an offset
        delta = g.op(
            "Sub",
            _slice(g, WINDOW_INPUT, w - 1, w, 1),
            _slice(g, WINDOW_INPUT, w - 2, w - 1, 1),
            stem="newest",
        )  # (b, 1, 1)
        if dt is not np.float32:
            delta = g.op("Cast", delta, to=DOUBLE)
        col = last_sample_column(estimator).reshape(1, 1, -1)
        y = g.op("Add", PARTIAL, g.op("Mul", delta, g.const(col, dt)), stem="dft")
        power = _power(g, y)
        value = _peak_value(
            g, power, _bin_positions(nfft), n1 * k2n, estimator, dt, scale, shift
        )
        prep_model = _prepare_graph(estimator, quantity, dft_dtype, opset, part)
    else:
        inp = helper.make_tensor_value_info(WINDOW_INPUT, FLOAT, ["batch", w, 1])
        x = g.op("Cast", WINDOW_INPUT, to=DOUBLE, stem="x")  # (b, W, 1)
        nfft = w * int(estimator.pad_factor)
        n1, k2n = _dims(nfft)
        power = _spectrum(g, x, estimator, dft_dtype, rank=3)
        value = _peak_value(
            g, power, _bin_positions(nfft), n1 * k2n, estimator, dt, scale, shift
        )
    note: dict[str, Any] = {}
    if quantity == "speed":
        score64, note = _speed(g, value, estimator, table)
    else:
        # f_d (Hz, bounded by the largest f_max); 0 (no peak) -> NO_SCORE
        score64 = g.op(
            "Where", g.op("Greater", value, _d(g, 0.0)), value, _d(g, NO_SCORE)
        )
    g.nodes.append(helper.make_node("Cast", [score64], [SCORE], to=FLOAT))
    unit = "mm/s" if quantity == "speed" else "Hz"
    lo, hi = (float(v) for v in estimator.f_max_range)
    model = g.build(
        [inp] if prep_model is None else [inp, part],
        [helper.make_tensor_value_info(SCORE, FLOAT, ["batch"])],
        doc=(
            f"StickSlipSpeed: {quantity} ({unit}) of the last {w} nib samples (eqs. 6-7, "
            f"f_max {lo:g}-{hi:g} Hz, eq. 3 {estimator.form} form)"
        ),
        extra_inputs=(PARTIAL,) if prep_model is not None else (),
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
            "prepare": bool(prepare),
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
        prepare=prep_model,
        prepare_tensor=PARTIAL if prep_model is not None else "",
    )


#: The tensor the prepare graph hands to the main graph (the DFT with the newest
#: sample held at the one before it, ``(batch, 1, 2 N1 K2)``).
PARTIAL = "partial"


def _prepare_graph(
    est: StickSlipSpeed,
    quantity: str,
    dft_dtype: str,
    opset: int,
    out: onnx.ValueInfoProto,
) -> onnx.ModelProto:
    """The prepare graph: the previous frame's window in, :data:`PARTIAL` out.

    The runtime runs it on the frame before a decision, on that frame's window (the
    main graph's input, one frame early). The decision's window is that window less
    its oldest sample plus the sample still to come; the graph drops the oldest and
    repeats the newest in its place (``[x[1:], x[-1]]``), then steps 1-2.
    """
    w = int(est.window)
    g = GraphBuilder(f"stick_slip_{quantity}_prepare", opset)
    inp = helper.make_tensor_value_info(WINDOW_INPUT, FLOAT, ["batch", w, 1])
    x = g.op("Cast", WINDOW_INPUT, to=DOUBLE, stem="x")
    v = g.op("Concat", _slice(g, x, 1, w, 1), _slice(g, x, w - 1, w, 1), axis=1)
    y = _dft(g, _windowed(g, v, est, 3), est, dft_dtype, 3)
    g.nodes.append(
        helper.make_node("Reshape", [y, g.const([0, 1, -1], np.int64)], [PARTIAL])
    )
    return g.build(
        [inp],
        [out],
        doc="StickSlipSpeed prepare: the DFT of the next window, its newest sample held",
    )


def incremental_problem(estimator: StickSlipSpeed) -> str | None:
    """Why ``estimator`` has no incremental export (None when it has one)."""
    from slipkit.runtime.ops.sliptack import check_sliding_grid

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


register_exporter(StickSlipSpeed, export_stick_slip_speed)

__all__ = [
    "QUANTITIES",
    "dft_matrices",
    "export_stick_slip_speed",
    "graph_speeds",
    "incremental_problem",
    "peak_ranks",
    "sliding_spectrum_step",
    "speed_table",
]
