"""Preprocessing that runs in numpy before the ONNX graph: a closed registry of named ops.

A bundle's ``preprocessing`` is a list of steps such as
``{"op": "standardize", "mean": [...], "scale": [...]}``. Each step names an op from
:data:`OPS` and gives its parameters as plain JSON; no code is ever loaded from a
bundle, so a bundle can only ask for what this module implements.

Steps act on the window, an array of shape ``(window, *frame.shape)`` (oldest frame
first), and each step's output feeds the next; the last output is reshaped to the
graph's input shape (same number of values, checked when the bundle loads). Prefer
putting math in the graph: preprocessing is for what an exporter cannot express
there, or what training did outside the estimator.

Ops preallocate their output buffers from the input shape they are compiled for, so
a frame costs no allocation beyond what the op's math needs.

===========================  =====================================================
op                           parameters, effect
===========================  =====================================================
``standardize``              ``mean``, ``scale`` (lists broadcast against the
                             trailing axes, ``scale > 0``): ``(x - mean) / scale``
``select``                   ``indices`` (list of int): ``x[..., indices]``
``diff``                     ``scale`` (number, default 1; e.g. the rate in Hz for a
                             derivative per s): ``(x[1:] - x[:-1]) * scale``
``pin_velocity_features``    ``variant`` (``dr_dtheta``/``dr``/``dtheta``),
                             ``shift_angles`` (bool, default true),
                             ``missing_count`` (bool, default false): TacTip pin
                             frames ``(w, 2N)`` (x block, y block, mm) ->
                             :func:`slipkit.features.pins.velocity_features` of
                             consecutive differences, ``(w - 1, F)``
``subtract``                 ``value`` (list broadcasting against the trailing
                             axes): ``x - value`` in float64 (e.g. a fixed
                             reference frame, so small offsets survive the
                             float32 cast of the graph input)
``subtract_first``           none: ``x - x[0]`` (each window minus its own first
                             frame)
``baseline_first``           ``frames`` (int >= 1), ``hop`` (int >= 1, the frame
                             hop): ``x`` minus the median of the first ``frames``
                             frames of the *stream* (stateful: collected from the
                             windows as they arrive; until ``frames`` frames have
                             arrived, the median of those that have)
``davis_areas``              ``opening_px``, ``closing_px`` (int 0..32, px),
                             ``opening_shape`` (``square``/``lines``),
                             ``min_area_px`` (int): one DAVIS event frame
                             ``(1, 2, H, W)`` (positive, negative event counts)
                             -> the filtered positive and negative areas
                             ``(1, 2)`` (px) of
                             :func:`slipkit.families.davis.polarity.clean_frame`
                             (opening, closing, 8-connected area filter)
``press_sign``               ``rest_frames``, ``block``, ``hop`` (int >= 1, hop a
                             multiple of block), ``delta`` (> 0), ``sign``
                             (optional: +1, -1 or 0, default 0): one channel
                             ``(w, 1)`` -> ``sign * (x - rest)``, the rest level
                             (and, for ``sign`` 0, the press direction) latched
                             from the *stream* (stateful): ``rest`` the mean of
                             its first ``rest_frames`` finite frames; ``sign``
                             fixed (+1: the voltage falls under a press, -1: it
                             rises) or, for 0, set by the stream's first block
                             mean further than ``delta`` from rest (+1 when below
                             it); zeros until both are known. The FSR detector's
                             per-stream rest level
                             (:class:`slipkit.families.fsr.touch_slip.FSRTouchSlip`, voltage
                             input; ``sign`` 0 for ``polarity="per_recording"``)
``contact_window``           ``arm``, ``window``, ``min_frames``, ``horizon``
                             (optional): one frame of ``2K`` pin positions ->
                             the window since contact in marker pitches and a
                             decide row ``(window + 1, 2K)``, the frame counter,
                             pitch and reference held from the *stream*
                             (stateful; :mod:`slipkit.runtime.ops.gelsight`)
===========================  =====================================================
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Any, Protocol

import numpy as np
from numpy.typing import NDArray

from slipkit._registry import Registry
from slipkit.runtime._schema import MAX_FRAMES, MAX_STEPS, MAX_VALUES, Fields

Array = NDArray[np.float64]


class Op(Protocol):
    """A compiled preprocessing step: a fixed input shape, a fixed output shape.

    An op may also set ``keeps_nonfinite`` (a bool, or a property for a stateful
    op): True when the output has the input's shape, each output value is its
    input value through arithmetic that keeps a NaN or infinity non-finite (minus
    or divided by a number > 0), so a NaN or infinity anywhere in the input comes
    out as a NaN or infinity, and the op holds no state a bad frame could reach
    right now.
    :class:`~slipkit.runtime.loop.StreamLoop` then tests the graph input alone for
    one-frame windows (the frame is tested only when that finds a NaN or
    infinity). Ops without it are never run on a frame before it is tested.

    Reset contract. An op that keeps anything between calls has ``reset()``, which
    forgets it (a new stream starts with the next call, whose window holds the
    stream's first frames). It also sets ``stream_state``: True when its output
    depends on frames before the window (``baseline_first``, ``press_sign``: a
    level latched at the stream's start), False when the state is only a cache of
    a function of the window (``sliding_spectrum``). A bundle with a
    ``stream_state`` op treats a gap as a new recording:
    :class:`~slipkit.runtime.loop.StreamLoop` resets those ops there and restarts
    the window at the frame after the gap, as it zeros a recurrent state (its
    module docstring, *Stream state*). Every op's ``reset()`` runs on
    :meth:`Pipeline.reset` and :meth:`~slipkit.runtime.loop.StreamLoop.reset`.
    """

    out_shape: tuple[int, ...]

    def __call__(self, x: Array) -> Array:
        """Transform one window (or the previous step's output)."""
        ...


#: op name -> builder ``(params, input shape) -> Op``. Builders check their parameters
#: against the input shape and raise :class:`~slipkit.runtime.errors.BundleError`
#: naming the field.
OPS: Registry[str, Callable[[Fields, tuple[int, ...]], Op]] = Registry(
    "preprocessing op", error=ValueError, n_args=2, key_type=str
)


def register_op(
    name: str,
) -> Callable[
    [Callable[[Fields, tuple[int, ...]], Op]], Callable[[Fields, tuple[int, ...]], Op]
]:
    """Add a builder to :data:`OPS` under ``name``; a second registration is refused."""

    def deco(
        builder: Callable[[Fields, tuple[int, ...]], Op],
    ) -> Callable[[Fields, tuple[int, ...]], Op]:
        return OPS.register(name, builder)

    return deco


def _broadcast_param(f: Fields, key: str, in_shape: tuple[int, ...]) -> Array:
    """A parameter array that must broadcast against ``in_shape`` without growing it."""
    arr = f.array(key)
    try:
        shape = np.broadcast_shapes(arr.shape, in_shape)
    except ValueError:
        shape = None
    if shape != in_shape:
        raise f.error(
            key,
            f"shape {list(arr.shape)} does not broadcast against the step's input "
            f"shape {list(in_shape)} (give one value per trailing-axis entry)",
        )
    return arr


class _Standardize:
    #: (x - mean) / scale with finite mean and scale > 0 (see :class:`Op`)
    keeps_nonfinite = True

    def __init__(self, mean: Array, scale: Array, in_shape: tuple[int, ...]) -> None:
        # Broadcast once, here: a ufunc on same-shape operands costs ~0.2 us on a
        # small window, one that broadcasts ~0.7 us (measured; per frame, it adds up).
        self.mean = np.ascontiguousarray(np.broadcast_to(mean, in_shape))
        self.scale = np.ascontiguousarray(np.broadcast_to(scale, in_shape))
        self.out_shape = in_shape
        self._buf = np.empty(in_shape)

    def __call__(self, x: Array) -> Array:
        np.subtract(x, self.mean, self._buf)
        np.divide(self._buf, self.scale, self._buf)
        return self._buf


@register_op("standardize")
def _standardize(f: Fields, in_shape: tuple[int, ...]) -> Op:
    f.only(("op", "mean", "scale"))
    mean = _broadcast_param(f, "mean", in_shape)
    scale = _broadcast_param(f, "scale", in_shape)
    if np.any(scale <= 0):
        raise f.error(
            "scale", "must be > 0 everywhere (a constant feature gets scale 1)"
        )
    return _Standardize(mean, scale, in_shape)


class _Select:
    def __init__(self, idx: NDArray[np.intp], in_shape: tuple[int, ...]) -> None:
        self.idx = idx
        self.out_shape = (*in_shape[:-1], len(idx))
        self._buf = np.empty(self.out_shape)

    def __call__(self, x: Array) -> Array:
        np.take(x, self.idx, axis=-1, out=self._buf)
        return self._buf


@register_op("select")
def _select(f: Fields, in_shape: tuple[int, ...]) -> Op:
    f.only(("op", "indices"))
    idx = f.integers("indices", minimum=0, maximum=MAX_VALUES)
    if len(idx) * math.prod(in_shape[:-1]) > MAX_VALUES:
        raise f.error(
            "indices",
            f"selects {len(idx)} entries of each of {math.prod(in_shape[:-1])} rows: "
            f"more than {MAX_VALUES} values",
        )
    if max(idx) >= in_shape[-1]:
        raise f.error(
            "indices",
            f"index {max(idx)} is out of range for a last axis of {in_shape[-1]}",
        )
    return _Select(np.asarray(idx, dtype=np.intp), in_shape)


class _Diff:
    def __init__(self, scale: float, in_shape: tuple[int, ...]) -> None:
        self.scale = scale
        self.out_shape = (in_shape[0] - 1, *in_shape[1:])
        self._buf = np.empty(self.out_shape)

    def __call__(self, x: Array) -> Array:
        np.subtract(x[1:], x[:-1], out=self._buf)
        if self.scale != 1.0:
            self._buf *= self.scale
        return self._buf


def _need_two_frames(f: Fields, in_shape: tuple[int, ...]) -> None:
    if in_shape[0] < 2:
        raise f.error(
            "op",
            f"needs a window of >= 2 frames (differences of consecutive frames); "
            f"the step's input has {in_shape[0]}",
        )


@register_op("diff")
def _diff(f: Fields, in_shape: tuple[int, ...]) -> Op:
    f.only(("op", "scale"))
    _need_two_frames(f, in_shape)
    return _Diff(f.number("scale", 1.0), in_shape)


class _PinVelocityFeatures:
    def __init__(
        self,
        fn: Callable[..., Array],
        kwargs: dict[str, Any],
        in_shape: tuple[int, ...],
    ) -> None:
        self._fn = fn
        self._kwargs = kwargs
        self._n = in_shape[1] // 2
        probe = fn(np.zeros((in_shape[0] - 1, self._n, 2)), **kwargs)
        self.out_shape = tuple(int(s) for s in probe.shape)
        self._dxy = np.empty((in_shape[0] - 1, self._n, 2))

    def __call__(self, x: Array) -> Array:
        # Stream layout is an x block then a y block (slipkit.families.tactip.physics.pin_channels);
        # velocity_features wants (..., N, 2).
        n = self._n
        np.subtract(x[1:, :n], x[:-1, :n], out=self._dxy[..., 0])
        np.subtract(x[1:, n:], x[:-1, n:], out=self._dxy[..., 1])
        return self._fn(self._dxy, **self._kwargs)


@register_op("pin_velocity_features")
def _pin_velocity_features(f: Fields, in_shape: tuple[int, ...]) -> Op:
    # Imported here, not at the top: slipkit.features.pins is numpy-only by contract
    # (the training features and the runtime's are then the same code), and bundles
    # without this op never load it.
    from slipkit.features.pins import VARIANTS, velocity_features

    f.only(("op", "variant", "shift_angles", "missing_count"))
    _need_two_frames(f, in_shape)
    if len(in_shape) != 2 or in_shape[1] % 2:
        raise f.error(
            "op",
            f"needs pin frames of shape (window, 2N) (x block then y block); "
            f"the step's input is {list(in_shape)}",
        )
    kwargs = {
        "variant": f.string("variant", "dr_dtheta", choices=VARIANTS),
        "shift_angles": f.boolean("shift_angles", True),
        "missing_count": f.boolean("missing_count", False),
    }
    return _PinVelocityFeatures(velocity_features, kwargs, in_shape)


class _Subtract:
    #: x - value with a finite value (see :class:`Op`)
    keeps_nonfinite = True

    def __init__(self, value: Array, in_shape: tuple[int, ...]) -> None:
        # Broadcast once (see _Standardize).
        self.value = np.ascontiguousarray(np.broadcast_to(value, in_shape))
        self.out_shape = in_shape
        self._buf = np.empty(in_shape)

    def __call__(self, x: Array) -> Array:
        np.subtract(x, self.value, self._buf)
        return self._buf


@register_op("subtract")
def _subtract(f: Fields, in_shape: tuple[int, ...]) -> Op:
    f.only(("op", "value"))
    return _Subtract(_broadcast_param(f, "value", in_shape), in_shape)


class _SubtractFirst:
    def __init__(self, in_shape: tuple[int, ...]) -> None:
        self.out_shape = in_shape
        self._buf = np.empty(in_shape)

    def __call__(self, x: Array) -> Array:
        np.subtract(x, x[0], self._buf)
        return self._buf


@register_op("subtract_first")
def _subtract_first(f: Fields, in_shape: tuple[int, ...]) -> Op:
    f.only(("op",))
    return _SubtractFirst(in_shape)


class _BaselineFirst:
    """``x`` minus the median of the stream's first ``n`` frames (state across calls).

    The first call sees a full window (stream frames ``0 .. w-1``); each later call
    adds the last ``hop`` rows of its window. Frames are collected until ``n`` have
    arrived; before that the baseline is the median of those seen so far, so a
    decision never waits for the baseline (training computed it from the trial's
    first ``n`` frames, future ones included: only the first ``n - 1`` frames of a
    stream can differ).
    """

    #: the baseline is latched from the stream's first frames (see :class:`Op`)
    stream_state = True

    def __init__(self, n: int, hop: int, in_shape: tuple[int, ...]) -> None:
        self.n = n
        self.hop = hop
        self.out_shape = in_shape
        self._buf = np.empty(in_shape)
        self._seen = np.empty((n, *in_shape[1:]))
        self.reset()

    def reset(self) -> None:
        """Forget the baseline (a new stream, e.g. the next grasp)."""
        self._count = 0
        self._started = False
        # The baseline repeated over the window's frames: a subtraction of equal
        # shapes skips numpy's broadcasting setup (~0.4 us per call on a 1 x 19 BioTac
        # window, a tenth of a force model's whole loop step).
        self._base = np.zeros(self.out_shape)

    @property
    def keeps_nonfinite(self) -> bool:
        """True once the baseline is complete (see :class:`Op`).

        From then on the op is ``x - base`` with a fixed base; before, each call adds frames to the baseline, so
        a frame must be tested before it reaches the op.
        """
        return self._count >= self.n

    def __call__(self, x: Array) -> Array:
        if self._count < self.n:
            new = x if not self._started else x[max(len(x) - self.hop, 0) :]
            self._started = True
            take = min(self.n - self._count, len(new))
            self._seen[self._count : self._count + take] = new[:take]
            self._count += take
            self._base[...] = np.median(self._seen[: self._count], axis=0)
        np.subtract(x, self._base, self._buf)
        return self._buf


@register_op("baseline_first")
def _baseline_first(f: Fields, in_shape: tuple[int, ...]) -> Op:
    f.only(("op", "frames", "hop"))
    n = f.integer("frames", minimum=1, maximum=MAX_FRAMES)
    if n * math.prod(in_shape[1:]) > MAX_VALUES:
        raise f.error(
            "frames",
            f"{n} frames of {math.prod(in_shape[1:])} values each exceed the "
            f"{MAX_VALUES} values a baseline may hold",
        )
    return _BaselineFirst(
        n, f.integer("hop", 1, minimum=1, maximum=MAX_FRAMES), in_shape
    )


class Pipeline:
    """Compiled preprocessing steps for one window shape.

    Parameters
    ----------
    steps : sequence of dict
        The manifest's ``preprocessing`` list.
    window_shape : tuple of int
        ``(window, *frame.shape)``.
    file : str
        Manifest file name for error messages.

    Attributes
    ----------
    ops : list of Op
        The compiled steps, in order.
    out_shape : tuple of int
        Shape of the last step's output (``window_shape`` when there are no steps).
    stateful : list of Op
        The steps with ``reset()`` (see :class:`Op`, *Reset contract*).
    stream_state : list of Op
        Of those, the steps whose output depends on frames before the window.
    """

    def __init__(
        self, steps: Sequence[object], window_shape: tuple[int, ...], file: str
    ) -> None:
        shape = tuple(window_shape)
        self.ops: list[Op] = []
        if len(steps) > MAX_STEPS:
            raise Fields(file, {}).error(
                "preprocessing", f"has {len(steps)} steps; at most {MAX_STEPS}"
            )
        for i, step in enumerate(steps):
            f = Fields(file, step, f"preprocessing[{i}]")
            name = f.string("op", choices=sorted(OPS))
            op = OPS[name](f, shape)
            shape = op.out_shape
            self.ops.append(op)
        self.out_shape = shape
        self.stateful: list[Op] = [op for op in self.ops if hasattr(op, "reset")]
        self.stream_state: list[Op] = [
            op for op in self.stateful if getattr(op, "stream_state", False)
        ]

    def reset(self) -> None:
        """Forget every step's state: the next window starts a new stream."""
        for op in self.stateful:
            op.reset()  # type: ignore[attr-defined]

    def __call__(self, window: Array) -> Array:
        """Run every step on one window (oldest frame first)."""
        for op in self.ops:
            window = op(window)
        return window


# -- ops of one sensor family each (slipkit.runtime.ops.<family>, registered on import) -----
from slipkit.runtime import ops as _ops  # noqa: E402, F401
