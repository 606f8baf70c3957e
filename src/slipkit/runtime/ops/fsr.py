"""The FSR family's runtime op ``press_sign``: rest level and press sign latched per stream (numpy only)."""

from __future__ import annotations

import math

import numpy as np

from slipkit.runtime._schema import MAX_FRAMES, Fields
from slipkit.runtime.preprocessing import Array, Op, register_op

# -- FSR press polarity: the rest level (and the wiring's sign) learned from the stream ------
# FSRTouchSlip takes each recording's rest level from its first samples and, with
# polarity="per_recording", its sign from its first press (slipkit.families.fsr.touch_slip). A
# graph holds constants only, so the rest level and the sign are latched here, in numpy
# (a fixed polarity gives the sign), and the graph reads the sign-normalised signal
# (rest 0, a press falling, slip rising: the paper's wiring).


def _left_mean(values: Array) -> float:
    """Mean of the finite ``values`` summed left to right (NaN if none).

    The detector's own rounding (``slipkit.families.fsr.touch_slip._sequential_sum``): numpy's
    pairwise sum could differ in the last bit, and the touch gate compares with it.
    """
    total, n = 0.0, 0
    for v in values.tolist():
        if math.isfinite(v):
            total += v
            n += 1
    return total / n if n else math.nan


class _PressSign:
    """One channel ``(w, 1)`` -> ``sign * (x - rest)`` with both taken from the stream.

    The first call sees the stream's first ``w`` frames; each later call ``hop`` new
    ones (the loop calls every ``hop`` frames). ``rest`` is the mean of the first
    ``rest_frames`` finite frames. A fixed ``sign`` (+1 or -1, a known wiring) is used
    as soon as ``rest`` is known. Otherwise (``sign`` 0) each call looks at the
    complete ``block``-frame means of its window that lie wholly after the rest period
    (stream block ``ceil(rest_frames / block)`` on, at least block 1; blocks are
    aligned to the stream's first frame, as the window is): the first one further than
    ``delta`` from ``rest`` latches ``sign`` (+1 when below rest, -1 when above). Every
    block of the window is looked at, not only the new ones, so a window the loop
    skipped (a flagged frame) loses no block that is still in the next window. Until
    both are known (and while ``rest`` is NaN: no finite rest frame) the output is
    zeros (untouched: the graph's touch gate scores it NO_SCORE).
    """

    #: rest and sign are latched from the stream's first frames (see :class:`Op`)
    stream_state = True

    def __init__(
        self,
        rest_n: int,
        block: int,
        hop: int,
        delta: float,
        in_shape: tuple[int, ...],
        sign: float = 0.0,
    ) -> None:
        self.rest_n, self.block, self.hop, self.delta = rest_n, block, hop, delta
        self.fixed_sign = float(sign)
        self.first_block = max(1, -(-rest_n // block))
        self.out_shape = in_shape
        self._nb = in_shape[0] // block
        self._buf = np.empty(in_shape)
        self._seen = np.empty(rest_n)
        self.reset()

    def reset(self) -> None:
        """Forget the rest level and a latched sign (a new stream, e.g. the next grasp)."""
        self._calls = 0
        self._count = 0
        self.rest = math.nan
        self.sign = self.fixed_sign

    def _collect(self, x: Array) -> None:
        new = x[:, 0] if self._calls == 0 else x[max(len(x) - self.hop, 0) :, 0]
        take = min(self.rest_n - self._count, len(new))
        self._seen[self._count : self._count + take] = new[:take]
        self._count += take
        if self._count == self.rest_n:
            self.rest = _left_mean(self._seen)

    def _latch(self, x: Array) -> None:
        b = self.block
        blocks = x[: self._nb * b, 0].reshape(self._nb, b)
        if b < 8:
            # numpy sums fewer than 8 values left to right, as the detector does (a
            # loop over the block's columns, 3x slower, gives the same bits)
            means = blocks.sum(axis=1)
        else:  # longer rows are summed pairwise: add the columns in order instead
            means = blocks[:, 0].copy()
            for j in range(1, b):
                means += blocks[:, j]
        means /= b
        np.subtract(means, self.rest, out=means)
        # stream block of the window's first block (calls every hop frames from 0);
        # the rest period's blocks never latch
        skip = self.first_block - (self._calls * self.hop) // b
        if skip > 0:
            means[:skip] = 0.0
        # NaN (a missing sample) compares False: its block never latches
        away = np.abs(means) > self.delta
        k = int(away.argmax())
        if away[k]:
            self.sign = -1.0 if means[k] > 0 else 1.0

    def __call__(self, x: Array) -> Array:
        if self._count < self.rest_n:
            self._collect(x)
        if self.sign == 0.0 and self._count == self.rest_n:
            self._latch(x)
        self._calls += 1
        if self.sign == 0.0 or math.isnan(self.rest):
            self._buf.fill(0.0)
        else:
            np.subtract(x, self.rest, self._buf)
            if self.sign < 0:
                np.negative(self._buf, self._buf)
        return self._buf


@register_op("press_sign")
def _press_sign(f: Fields, in_shape: tuple[int, ...]) -> Op:
    f.only(("op", "rest_frames", "block", "hop", "delta", "sign"))
    if len(in_shape) != 2 or in_shape[1] != 1:
        raise f.error(
            "op",
            f"needs one channel, a window of shape (window, 1); the step's input is "
            f"{list(in_shape)}",
        )
    rest_n = f.integer("rest_frames", minimum=1, maximum=MAX_FRAMES)
    block = f.integer("block", minimum=1, maximum=in_shape[0])
    hop = f.integer("hop", minimum=1, maximum=MAX_FRAMES)
    if hop % block:
        raise f.error(
            "hop",
            f"must be a multiple of block ({block}) so that windows end on "
            f"block ends; got {hop}",
        )
    if in_shape[0] % block:
        raise f.error(
            "block",
            f"must divide the window ({in_shape[0]} frames) so that it holds whole "
            f"blocks; got {block}",
        )
    delta = f.number("delta", positive=True)
    sign = f.integer("sign", 0, minimum=-1, maximum=1)
    return _PressSign(rest_n, block, hop, delta, in_shape, float(sign))
