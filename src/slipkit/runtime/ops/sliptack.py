"""The SlipTack power spectrum updated per hop: a sliding DFT of the detrended, Hamming-weighted window.

:func:`slipkit.families.sliptack.speed.dominant_frequency` takes, per decision, the last
``W`` nib samples ``x[0..W-1]``, subtracts their centred ``s``-sample moving average
(``scipy.ndimage.uniform_filter1d``, ``mode="nearest"``), multiplies by
``numpy.hamming(W)`` and takes the real DFT of length ``nfft``. All of it is linear
in ``x``: bin ``k`` is ``Y_k = sum_m K[k, m] x[m]`` for a fixed matrix ``K``. The full
transform costs ``O(W nfft)`` per decision (0.13 M multiply-adds as the graph's
two-stage MatMuls); this op updates ``Y`` from the previous decision's with the
``hop`` new samples instead.

Why that works. Hamming is ``0.54 - 0.46 cos(2 pi m / (W - 1))``, so each row of the
windowed DFT is a sum of three complex exponentials in ``m`` (frequencies
``nu = w_k`` and ``w_k +- 2 pi / (W - 1)``, ``w_k = 2 pi k / nfft``): three
rectangular sliding DFTs. The moving average adds, on each of three ranges of
``m`` (``[0, s - l)``, ``[s - l, W - l)``, ``[W - l, W)`` with ``l = s // 2``), the
partial sums of those exponentials: again a constant plus the same exponentials;
the clipped edges add one term in ``x[0]`` and one in ``x[W - 1]``. So per range
``r`` and bin ``k``, ``K[k, m] = sum_f beta[k, f, r] exp(-i nu_f m)`` over four
frequencies ``f`` (0 and the three above). The coefficients ``beta`` are fitted
here, once, by least squares to ``K`` computed column by column with
``numpy.fft.rfft`` (the fit must be exact to ~1e-9 of ``max |K|``, else the op
refuses to build), instead of being derived by hand.

A range sum ``sum_{m in [a, b)} x[t0 + m] exp(-i nu m)`` is ``exp(i nu t0) (Q(t0 + b -
1) - Q(t0 + a - 1))`` with the running sums ``Q_nu(t) = sum_{u <= t} x[u] exp(-i nu
u)`` since the stream (re)started. Keeping ``Q`` at every decision instant (every
``hop`` samples) in a ring of ``W / hop + 1`` entries gives every range boundary,
provided they lie on the hop grid (``W``, ``s - l`` and ``l`` multiples of ``hop``:
true for SlipTack's 1000 / 300 / 10 and 300 / 300 / 10; the builder refuses
otherwise). Per decision: ``Q += P * (x_new @ E)`` (``hop x 2F`` real MatMul, ``F =
3 nb + 1`` frequencies), then ``Y`` as a weighted sum of four ring entries, then
``|Y|^2``. ``Q`` runs in float64 with the first sample subtracted, so window sums
stay exact to ~1e-10 relative over hours at 1 kHz.

State and resets. The op keeps a copy of its previous window. A call whose window
is not the previous one moved by ``hop`` (the first call, a window the loop skipped
for a bad frame, a reset) rebuilds ``Q`` from the window itself in ``O(W F)`` (a
few ms for ``W = 1000``: one slow decision per restart); a non-finite sample
makes the output NaN and forces that rebuild on the next call. An exactly constant
window gives zeros (the batch estimator's "flat window": no peak).

Standard library and numpy only (:mod:`slipkit.runtime`'s rule); scipy's
``uniform_filter1d`` is rebuilt as a matrix for the fit.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from slipkit.runtime._schema import MAX_FRAMES, Fields
from slipkit.runtime.preprocessing import Op, register_op

Array = NDArray[np.float64]
#: Largest W x F product the op builds (W samples x F sliding frequencies).
MAX_WORK = 1 << 24
#: Relative residual above which a bin's fitted decomposition is not used.
FIT_TOL = 1e-9
#: Most bins computed directly (``K[k] . x``) where the fit does not hold (DC).
MAX_DIRECT = 8


def detrend_matrix(w: int, s: int) -> Array:
    """``I - M``: the residual of the centred ``s``-sample moving average, edges repeated.

    ``M[n, clip(j)] += 1 / s`` for ``j = n - s // 2 .. n - s // 2 + s - 1``, as
    ``scipy.ndimage.uniform_filter1d(x, s, mode="nearest")``.
    """
    left = s // 2
    m = np.zeros((w, w))
    n = np.arange(w)
    for j in range(s):
        np.add.at(m, (n, np.clip(n - left + j, 0, w - 1)), 1.0 / s)
    return np.eye(w) - m


def spectrum_matrix(w: int, s: int, nfft: int) -> NDArray[np.complex128]:
    """``K`` (nfft // 2 + 1, w): the DFT bins of the detrended, Hamming-weighted window."""
    a = np.hamming(w)[:, None] * detrend_matrix(w, s)
    return np.fft.rfft(a, n=nfft, axis=0)


def range_bounds(w: int, s: int) -> list[int]:
    """Window positions where ``K``'s rows change form: ``0, s - l, w - l, w`` (deduplicated)."""
    left = s // 2
    return sorted({0, min(max(s - left, 0), w), max(w - left, 0), w})


class SlidingSpectrum:
    """Window ``(W, 1)`` -> power spectrum ``(1, nfft // 2 + 1)``, updated per hop (module docstring)."""

    #: the state is a cache of a function of the window (preprocessing.Op)
    stream_state = False

    def __init__(self, w: int, s: int, hop: int, nfft: int) -> None:
        self.w, self.s, self.hop, self.nfft = w, s, hop, nfft
        nb = nfft // 2 + 1
        self.out_shape: tuple[int, ...] = (1, nb)
        bounds = range_bounds(w, s)
        self._lags = [(w - p) // hop for p in bounds]  # ring lag of each boundary
        self._nring = w // hop + 1
        # frequencies: 0, then w_k, then w_k - a, then w_k + a (k = 0 .. nb - 1), so
        # that bin k's three are 1 + k + j nb and the three sums add as contiguous blocks
        a = 2.0 * math.pi / (w - 1)
        wk = 2.0 * math.pi * np.arange(nb) / nfft
        nu = np.concatenate([[0.0], wk, wk - a, wk + a])
        self._nu = nu
        nf = len(nu)
        fidx = np.stack(
            [
                np.zeros(nb, dtype=np.intp),
                *(1 + np.arange(nb) + j * nb for j in range(3)),
            ]
        )  # (4, nb): the frequencies of bin k
        kmat = spectrum_matrix(w, s, nfft)  # (nb, w)
        m = np.arange(w)
        # beta per range, then G per boundary: range r's sum is Q(b_{r+1}) - Q(b_r)
        g = np.zeros((len(bounds), 4, nb), dtype=np.complex128)
        self._d0 = kmat[:, 0].copy()
        self._d1 = kmat[:, w - 1].copy()
        scale = float(np.abs(kmat).max())
        direct: set[int] = set()
        for r in range(len(bounds) - 1):
            lo, hi = bounds[r], bounds[r + 1]
            pts = m[lo:hi]
            fit_pts = pts[(pts != 0) & (pts != w - 1)]
            for k in range(nb):
                basis = np.exp(-1j * np.outer(m, nu[fidx[:, k]]))  # (w, 4)
                beta = np.linalg.lstsq(basis[fit_pts], kmat[k, fit_pts], rcond=None)[0]
                approx = basis[pts] @ beta
                resid = kmat[k, pts] - approx
                bad = np.abs(resid[(pts != 0) & (pts != w - 1)])
                if bad.size and float(bad.max()) > FIT_TOL * scale:
                    # e.g. DC: the moving average's partial sums of exp(0) grow
                    # linearly, not as an exponential; such a bin is a direct dot
                    direct.add(k)
                    continue
                if lo == 0:
                    self._d0[k] -= approx[0]
                if hi == w:
                    self._d1[k] -= approx[-1]
                g[r + 1, :, k] += beta
                g[r, :, k] -= beta
        if len(direct) > MAX_DIRECT:
            raise ValueError(
                f"sliding spectrum: {len(direct)} bins are not sums of their "
                f"exponentials (at most {MAX_DIRECT} are computed directly)"
            )
        self.direct = np.array(sorted(direct), dtype=np.intp)
        g[:, :, self.direct] = 0.0
        self._d0[self.direct] = 0.0
        self._d1[self.direct] = 0.0
        # direct bins: Y_k = K[k] . x, as a real (2 n_direct, W) matrix
        kd = kmat[self.direct]
        self._kd = np.ascontiguousarray(np.concatenate([kd.real, kd.imag]))
        self._yd = np.zeros(2 * len(self.direct))
        # exp(i nu t0) with t0 = d hop and P = exp(-i nu (W / hop - 1 + d) hop):
        # exp(i nu t0) = conj(P) exp(-i nu (W - hop)), folded into G. Frequencies
        # 1.. are bin k's three (1 + k + j nb) one to one: G over them is elementwise;
        # frequency 0 (every bin's slot 0) is a small (nb, n_bounds) matrix.
        c = np.exp(-1j * nu * (w - hop))
        self._g_exp = np.ascontiguousarray(
            g[:, 1:, :] * c[1:].reshape(3, nb)[None]
        ).reshape(len(bounds), 3 * nb)  # (n_bounds, 3 nb): frequency 1 + i
        self._g_dc = np.ascontiguousarray(g[:, 0, :].T)  # (nb, n_bounds), c = 1
        self._nb, self._nf = nb, nf
        jj = np.arange(hop)
        e = np.exp(-1j * np.outer(jj, nu))  # (hop, F): block-relative phases
        # interleaved re, im columns: the MatMul writes the complex increment in place
        self._e = np.ascontiguousarray(e.view(np.float64))
        self._step = np.exp(-1j * nu * hop)
        # each block's phase in a rebuild, made once: a rebuild (the first call, a
        # gap) then costs one MatMul and a cumsum, ~1 ms for W = 1000, not ~10 ms
        self._blk_phase = np.exp(-1j * np.outer(np.arange(w // hop) * hop, nu))
        self._rb_x = np.zeros(w)
        self._rb = np.zeros((w // hop, 2 * nf))
        # buffers
        self._ring = np.zeros((self._nring, nf), dtype=np.complex128)
        self._phase = np.ones(nf, dtype=np.complex128)
        self._prev = np.zeros(w)
        self._neq = np.zeros(w - hop, dtype=bool)
        self._blk = np.zeros(hop)
        self._inc = np.zeros(nf, dtype=np.complex128)
        self._inc_f = self._inc.view(np.float64)
        self._dcq = np.zeros(len(bounds), dtype=np.complex128)
        self._conj = np.zeros(3 * nb, dtype=np.complex128)
        self._acc = np.zeros(3 * nb, dtype=np.complex128)
        self._tmpc = np.zeros(3 * nb, dtype=np.complex128)
        self._ydc = np.zeros(nb, dtype=np.complex128)
        self._y = np.zeros(nb, dtype=np.complex128)
        self._tmp = np.zeros(nb)
        self._buf = np.zeros(self.out_shape)
        self._pw = self._buf.reshape(-1)
        self.reset()

    def reset(self) -> None:
        """Forget the stream: the next call rebuilds the sums from its window."""
        self._valid = False
        self._head = 0
        self._ref = 0.0
        self.rebuilds = 0

    def _rebuild(self, x: Array) -> None:
        """``Q`` at every hop boundary of the window ``x`` (the stream starts at its first sample)."""
        w, h = self.w, self.hop
        self._ref = float(x[0])
        nblk = w // h
        # into buffers made once: fresh MB-sized arrays cost page faults (ms)
        np.subtract(x, self._ref, out=self._rb_x)
        np.matmul(self._rb_x.reshape(nblk, h), self._e, out=self._rb)
        inc = self._rb.view(np.complex128)
        inc *= self._blk_phase
        # ring slot of lag j (0 = now) is (head - j) mod nring; now = last block
        self._head = nblk
        self._ring[0] = 0.0  # Q(-1), lag nblk
        np.cumsum(inc, axis=0, out=self._ring[1 : nblk + 1])
        self._phase[...] = np.exp(-1j * self._nu * ((nblk - 1) * h))
        self.rebuilds += 1

    def _advance(self, x: Array) -> None:
        """Add the window's last ``hop`` samples to ``Q`` and store it in the ring."""
        np.subtract(x[-self.hop :], self._ref, out=self._blk)
        inc = self._inc
        np.matmul(self._blk, self._e, out=self._inc_f)
        self._phase *= self._step
        inc *= self._phase
        head = self._head
        nxt = head + 1
        if nxt == self._nring:
            nxt = 0
        np.add(self._ring[head], inc, out=self._ring[nxt])
        self._head = nxt

    def __call__(self, x: Array) -> Array:
        xs = x.reshape(-1)
        h = self.hop
        cont = False
        if self._valid:
            np.not_equal(xs[:-h], self._prev[h:], out=self._neq)
            cont = not self._neq.any()
        # a sum is finite only when every term is (inf - inf is NaN): one reduction
        if not math.isfinite(float(np.add.reduce(xs[-h:] if cont else xs))):
            self._valid = False
            self._pw.fill(math.nan)
            return self._buf
        if cont:
            self._advance(xs)
        else:
            self._rebuild(xs)
            self._valid = True
        np.copyto(self._prev, xs)
        if xs.max() == xs.min():  # a constant window: no spectrum (batch: flat)
            self._pw.fill(0.0)
            return self._buf
        # Y = conj(P)[f] * sum_q G[q] Q_q[f] + d0 x[0] + d1 x[W-1]
        nring, head = self._nring, self._head
        acc, tmp = self._acc, self._tmpc
        acc.fill(0.0)
        for q, lag in enumerate(self._lags):
            row = self._ring[(head - lag) % nring]
            np.multiply(self._g_exp[q], row[1:], out=tmp)
            acc += tmp
            self._dcq[q] = row[0]
        np.conjugate(self._phase[1:], out=self._conj)
        acc *= self._conj
        nb = self._nb
        np.add(acc[:nb], acc[nb : 2 * nb], out=self._y)
        self._y += acc[2 * nb :]
        np.matmul(self._g_dc, self._dcq, out=self._ydc)
        self._y += self._ydc
        # every sum is of x - ref (K 1 = 0: the same spectrum as of x)
        np.multiply(self._d0, xs[0] - self._ref, out=self._ydc)
        self._y += self._ydc
        np.multiply(self._d1, xs[-1] - self._ref, out=self._ydc)
        self._y += self._ydc
        if len(self.direct):
            np.matmul(self._kd, xs, out=self._yd)
            nd = len(self.direct)
            self._y[self.direct] = self._yd[:nd] + 1j * self._yd[nd:]
        np.multiply(self._y.real, self._y.real, out=self._pw)
        np.multiply(self._y.imag, self._y.imag, out=self._tmp)
        self._pw += self._tmp
        return self._buf


def check_sliding_grid(w: int, s: int, hop: int) -> str | None:
    """Why ``(window, detrend_frames, hop)`` has no sliding form (None when it has)."""
    s = min(s, w)
    if w < 4 or hop < 1 or hop >= w:
        return f"needs 1 <= hop < window and window >= 4; got window {w}, hop {hop}"
    bad = [p for p in range_bounds(w, s) if (w - p) % hop]
    if bad:
        return (
            f"the detrend's range boundaries {bad} (window {w}, detrend_frames {s}) "
            f"are not on the hop grid ({hop} samples)"
        )
    return None


@register_op("sliding_spectrum")
def _sliding_spectrum(f: Fields, in_shape: tuple[int, ...]) -> Op:
    f.only(("op", "detrend_frames", "hop", "nfft"))
    if len(in_shape) != 2 or in_shape[1] != 1:
        raise f.error(
            "op",
            f"needs one channel, a window of shape (window, 1); the step's input is "
            f"{list(in_shape)}",
        )
    w = in_shape[0]
    s = min(f.integer("detrend_frames", minimum=1, maximum=MAX_FRAMES), w)
    hop = f.integer("hop", minimum=1, maximum=MAX_FRAMES)
    nfft = f.integer("nfft", w, minimum=w, maximum=MAX_FRAMES)
    why = check_sliding_grid(w, s, hop)
    if why is not None:
        raise f.error("hop", why)
    if w * (3 * (nfft // 2 + 1) + 1) > MAX_WORK:
        raise f.error(
            "nfft",
            f"window {w} x {3 * (nfft // 2 + 1) + 1} sliding frequencies exceeds "
            f"{MAX_WORK}",
        )
    try:
        return SlidingSpectrum(w, s, hop, nfft)
    except ValueError as exc:
        raise f.error("op", str(exc)) from None


__all__ = [
    "SlidingSpectrum",
    "check_sliding_grid",
    "detrend_matrix",
    "range_bounds",
    "spectrum_matrix",
]
