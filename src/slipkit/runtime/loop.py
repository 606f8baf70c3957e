"""The streaming decision loop: ring buffer -> preprocessing -> one onnxruntime call -> rule -> debounce.

Per frame, :meth:`StreamLoop.step` copies the frame into a preallocated ring buffer;
once a window is full and on every ``hop``-th frame it runs the bundle's
preprocessing, writes the result into a preallocated graph input, calls the session
once for the score output only, applies the decision rule (``score >= threshold``, with
the class order and strictness of :class:`~slipkit.runtime.bundle.DecisionSpec`, or
``argmax`` in the slip classes) and the debounce (slip is *declared* on the ``k``-th
consecutive slip decision, as :func:`slipkit.models.online.debounce` does offline).
Latency runs from the frame's arrival (``time.perf_counter_ns`` taken by the source)
to the declared decision, so it includes buffering and preprocessing; writing the
record into the result arrays comes after the clock stops.

Ring buffer
-----------
Each frame is written twice, at slot ``i`` and ``i + window`` of a ``2 * window``
buffer, so the latest window is always the contiguous slice ``ring[j : j + window]``
(oldest frame first): O(1) per frame and no copy to hand the window to numpy or
onnxruntime. (``collections.deque`` or ``np.roll`` would cost a copy of the whole
window per frame.)

Bad frames
----------
A live stream must not stop on one bad frame, and a bad frame must not be scored as if
it were good. :meth:`StreamLoop.step` checks every frame and *flags* (never raises on)
one that is bad for one of these reasons (:data:`BAD_REASONS`):

``dtype``
    values that are not real numbers (strings, objects, complex, bool);
``shape``
    values whose shape is not the manifest's ``frame.shape`` (or a ragged list);
``nonfinite``
    a NaN or an infinity among the values (only an infinity for streams whose NaN
    means "missing", :data:`NAN_IS_MISSING_STREAMS`: a TacTip pin the camera lost is
    NaN in x and y, and the pin features treat it as absent);
``timestamp``
    a timestamp that is NaN, infinite or not a number;
``duplicate_time``
    the same timestamp as the previous frame (dt = 0);
``time_order``
    a timestamp before the previous frame's (out of order, or the clock went back).

A flagged frame still takes its place in the stream (a shape or dtype fault is stored
as NaN), so every window that contains it is *skipped*: no model call, no decision
record, and the debounce run restarts (slip is declared only on ``k`` consecutive
*valid* slip decisions). A *gap*, a timestamp more than ``max_gap_periods`` frame
periods after the previous one (dropped frames), is not a bad frame: it is counted,
and its windows are scored as the offline features score windows across dropped
frames (frame by frame), unless ``skip_gaps=True`` skips the windows holding frames
from both sides of it, or the bundle has stream state (below), where a gap starts a
new recording. Jitter (any dt in ``(0, max_gap_periods / rate_hz]``) is
accepted. Time is compared with the previous frame's finite timestamp, so one
glitched timestamp flags at most one frame (and counts at most one gap), and a
clock that restarts flags a single frame. A window whose graph input (float32, after
preprocessing) or score is NaN or infinite - finite frames can still overflow
float32 - is skipped and counted as well (numpy warns once about the cast). The
counts, the flagged frames with their reasons and the skipped windows are in
:class:`LoopResult` and its :meth:`~LoopResult.summary`.

The check costs one ``np.isfinite`` (``np.isinf`` where NaN means missing) into a
preallocated buffer, a shape and dtype comparison and one subtraction per frame, and
the same value check on the graph input per decision; only a bad frame takes the
slower path that names the reason. With hop 1, NaN never "missing" and preprocessing
ops that keep a NaN or infinity non-finite (``keeps_nonfinite`` in
:mod:`slipkit.runtime.preprocessing`), a frame completing a clean window skips its own
value check: the graph input's check covers it, and only an input that fails it has
the frame tested, to name it (``StreamLoop._step_hop1``; same results as the full
path). ``benchmarks/bench_runtime_loop.py`` and ``benchmarks/bench_deploy.py`` measure
the loop's per-frame latency with these checks in place.

Recurrent state
---------------
A bundle whose manifest lists ``state`` (a frame-by-frame recurrent model: frame and
``h`` in, score and ``h_next`` out) has each state tensor in a preallocated buffer
fed to the graph beside the frame input; its output lands in a second preallocated
buffer (bound once through the IOBinding) and is copied into the first after every
scored window, so no array is allocated per frame. The state starts at zeros and is
set back to zeros on a flagged frame, a gap, a window skipped because its graph
input or score was not finite, and :meth:`StreamLoop.reset`: the first window scored
after any of these starts from a fresh state, as if a new recording began there.
Each such event is counted (``state_resets``). A stateful bundle never takes the
hop-1 fast path (``_step_hop1``): :meth:`StreamLoop.step` handles the state.

Stream state
------------
A bundle with a recurrent ``state`` or a preprocessing op whose output depends on
frames before the window (``stream_state`` in :mod:`slipkit.runtime.preprocessing`:
``baseline_first``, ``press_sign``) reads a long gap (more than
``restart_gap_periods`` frame periods, default :data:`RESTART_GAP_PERIODS`) as the
start of a new recording, as the batch model reads each recording from its own
start: the frame after the gap is the new stream's first frame. A shorter gap (a few
dropped frames of a live stream) is counted and zeroes a recurrent state but keeps
the ops' rest level and wiring: the grasp goes on. Those ops are reset there, the state is zeroed, and the
window refills from that frame: windows holding frames from both sides are not
scored, and the hop grid restarts, so the first decision is on the new stream's
``window``-th frame and the next ones every ``hop`` frames, as at the start of the
loop. A flagged frame or a non-finite window does not reset the ops (the batch
models skip a missing sample within a recording). The work happens on the gap path
only; a frame in step pays nothing for it.

Prepared decisions
------------------
A bundle with a ``prepare`` graph (manifest ``prepare``; the SlipTack speed graph)
splits each decision's work in two. On the frame *before* a decision frame the loop
writes that frame's window into the graph input and runs the prepare graph, whose
output lands in a preallocated buffer bound as the main graph's second input; the
decision frame then runs only the main graph. The work that does not need the newest
frame is done one frame early, on a frame that otherwise only stores its values, and
each frame's latency holds one of the two parts. The prepare frames' latency (arrival
to the end of the prepare call; for hop 1 that frame's decision included) is recorded
too (``prepare`` in the summary), and the budget is judged on the decision and
prepare frames pooled (:mod:`slipkit.runtime.budget`). A decision whose prepare did not run on the frame before (a direct call of
:meth:`StreamLoop.step` after a skipped frame) runs it first, on the previous window
(counted as ``late``): the score is the same, only slower. The prepare call skips the
value check: its input's oldest frame is not part of the next window (and is dropped
by the graph), and the decision still checks the window it scores.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Iterable
from typing import Any

import numpy as np
import onnxruntime as ort
from numpy.typing import ArrayLike, NDArray

from slipkit.runtime.bundle import MODEL_FILE, Bundle
from slipkit.runtime.errors import BundleError
from slipkit.runtime.result import BAD_REASONS, LoopResult, latency_summary
from slipkit.runtime.session import ORT_ERRORS
from slipkit.runtime.sources import Frame

# Module-level names for _step_hop1: a global load instead of a global and an
# attribute load, twice per frame.
_clock = time.perf_counter_ns
_ndarray = np.ndarray

#: Frame periods of silence after which a bundle with stream state starts a new
#: recording (module docstring, *Stream state*): well above a few dropped frames of a
#: live stream, below the ten periods a replay or a parity stream leaves between trials.
RESTART_GAP_PERIODS = 5.0

#: Streams whose NaN values are data ("not detected"), not faults: the TacTip pins.
NAN_IS_MISSING_STREAMS = frozenset({"pins"})


class StreamLoop:
    """Decide slip frame by frame with a bundle's session.

    Parameters
    ----------
    bundle : Bundle
        A loaded bundle (:func:`slipkit.runtime.load_bundle`).
    io_binding : bool
        Run through an onnxruntime IOBinding with the input and the score output
        bound once to preallocated arrays (default), instead of ``session.run``
        (which builds a feed, allocates its output and returns a list each call).
        ``benchmarks/bench_runtime_loop.py`` measures both side by side: the
        binding saved about 1.4 us per call on this machine (``docs/deploy.md``).
    capacity : int
        Initial number of decision records (grows by doubling).
    max_gap_periods : float
        A timestamp more than this many frame periods (``1 / frame.rate_hz``, s)
        after the previous one is a gap (dropped frames), counted in the result.
        The default 1.5 accepts any jitter below half a period and catches one
        dropped frame.
    skip_gaps : bool
        Also skip the windows that span a gap (default False: score them, as the
        offline features do).
    restart_gap_periods : float
        For a bundle with stream state (module docstring, *Stream state*): a gap of
        more than this many frame periods starts a new recording (its ops reset);
        a shorter one does not. Default :data:`RESTART_GAP_PERIODS`; at least
        ``max_gap_periods``.
    nan_is_missing : bool, optional
        Let NaN values through (only infinities are flagged) because the bundle's
        preprocessing or graph reads NaN as "missing". Default: True when every
        stream of ``frame.streams`` is in :data:`NAN_IS_MISSING_STREAMS`.
    on_decision : callable, optional
        Called on every decision, after its latency clock stops and its record is
        stored, as ``on_decision(frame, timestamp, score, klass, slip, declared,
        latency_ns)`` (frame index, sensor time s or NaN, score, class index or -1,
        slip flag, debounced state, arrival -> decision ns): plain Python scalars,
        no record object per frame. :mod:`slipkit.runtime.sinks` holds the UDP and
        JSON lines sinks. Its time is not in the latency; an exception it raises
        propagates out of :meth:`step`.

    Attributes
    ----------
    n_frames : int
        Frames pushed since construction or :meth:`reset`.
    n_bad : int
        Frames flagged since construction or :meth:`reset`.
    last_bad : str or None
        Why the latest frame was flagged (:data:`BAD_REASONS`); None when it was good.
    """

    def __init__(
        self,
        bundle: Bundle,
        *,
        io_binding: bool = True,
        capacity: int = 1024,
        max_gap_periods: float = 1.5,
        skip_gaps: bool = False,
        restart_gap_periods: float | None = None,
        nan_is_missing: bool | None = None,
        on_decision: Callable[[int, float, float, int, bool, bool, int], Any]
        | None = None,
    ) -> None:
        if not (isinstance(max_gap_periods, int | float) and max_gap_periods > 1.0):
            raise ValueError(
                f"max_gap_periods must be a number above 1 (frame periods); got {max_gap_periods!r}"
            )
        restart = (
            RESTART_GAP_PERIODS if restart_gap_periods is None else restart_gap_periods
        )
        if not (
            isinstance(restart, int | float)
            and math.isfinite(restart)
            and restart >= max_gap_periods
        ):
            raise ValueError(
                "restart_gap_periods must be a finite number of frame periods at least "
                f"max_gap_periods ({max_gap_periods}); got {restart_gap_periods!r}"
            )
        m = bundle.manifest
        self.bundle = bundle
        self.on_decision = on_decision
        self._restart_dt = float(restart) / m.frame.rate_hz
        self._w = m.frame.window
        self._hop = m.frame.hop
        self._k = m.debounce_k
        self._shape = tuple(m.frame.shape)
        self._max_dt = float(max_gap_periods) / m.frame.rate_hz
        self._skip_gaps = bool(skip_gaps)
        self._ring = np.zeros((2 * self._w, *m.frame.shape))
        if nan_is_missing is None:
            nan_is_missing = bool(m.frame.streams) and (
                set(m.frame.streams) <= NAN_IS_MISSING_STREAMS
            )
        self.nan_is_missing = bool(nan_is_missing)
        # The value check writes into a preallocated bool buffer and compares its
        # bytes with those of a good result (all True for isfinite; all False for
        # isinf, where NaN means "missing"): one memcmp, ~0.14 us less per check
        # than searching the bytes for a bad one (bytes.__contains__ with a bytes
        # needle), and far less than ndarray.all() (~0.5 us).
        self._check = np.isinf if self.nan_is_missing else np.isfinite
        good = b"\x00" if self.nan_is_missing else b"\x01"
        self._finite = np.zeros(m.frame.shape, dtype=bool)
        self._frame_ok = good * self._finite.size
        self._windows = [self._ring[j : j + self._w] for j in range(self._w)]
        # Row views made once: indexing the ring per frame costs a view each time.
        self._rows = list(self._ring)
        self._ops = list(bundle.preprocessing.ops)
        # Stream state (module docstring): the ops reset on a gap, and whether a gap
        # restarts the stream (set below, once the recurrent state is known).
        self._stream_ops = list(bundle.preprocessing.stream_state)
        (inp,) = m.inputs
        assert inp.dtype is not None
        self._input = np.zeros(inp.static_shape, dtype=np.dtype(inp.dtype))
        # The graph input seen in the preprocessing's output shape (same values, a
        # view): writing the window into it needs no reshape per frame.
        self._input_view = self._input.reshape(bundle.preprocessing.out_shape)
        # The check runs on a flat view (a 1-D ufunc call is the cheaper one).
        self._input_flat = self._input.reshape(-1)
        self._input_finite = np.zeros(self._input.size, dtype=bool)
        self._input_ok = good * self._input.size
        self._feed = {inp.name: self._input}
        # Recurrent state (module docstring): h_in buffers fed to the graph, h_out
        # buffers the graph writes, copied into h_in after each scored window.
        self._state = m.state
        self._restart_on_gap = bool(self._stream_ops or self._state)
        self._h_in = [np.zeros(s.shape, dtype=np.dtype(s.dtype)) for s in m.state]
        self._h_out = [np.zeros_like(h) for h in self._h_in]
        self._h_pairs = tuple(zip(self._h_in, self._h_out, strict=True))
        self._feed.update(
            {s.input: h for s, h in zip(m.state, self._h_in, strict=True)}
        )
        # Prepared decisions (module docstring): the prepare graph's output buffer,
        # fed to the main graph as its second input.
        self._prep = bundle.prepare_session if m.prepare is not None else None
        self._prep_binding: ort.IOBinding | None = None
        self._prepared_for = -1
        if self._prep is not None:
            assert m.prepare is not None
            self._prep_name = m.prepare
            self._prep_feed = {inp.name: self._input}
            probe_p = self._prep.run([m.prepare], self._prep_feed)[0]
            self._partial = np.zeros_like(np.asarray(probe_p))
            self._feed[m.prepare] = self._partial
            self._late_input = np.zeros_like(self._input)
        d = m.decision
        self._out_names = [d.output, *(s.output for s in m.state)]
        self._argmax = d.rule == "argmax"
        self._col = d.column
        # argmax: the slip columns as an index array (max over them is the score) and
        # a lookup table class index -> is slip.
        self._slip_cols = np.asarray(d.slip_columns or (d.column,), dtype=np.intp)
        self._one_slip_col = len(self._slip_cols) == 1
        self._classes = d.classes
        self._has_classes = d.classes is not None
        self._thr = -math.inf if d.threshold is None else d.threshold
        self._strict = d.strict
        self._slip_above = d.slip_above
        self._session = bundle.session
        self._binding: ort.IOBinding | None = None
        probe = np.asarray(self._session.run(self._out_names, self._feed)[0])
        # A tuple of Python bools: indexing it is cheaper than a numpy array per call.
        self._is_slip = tuple(
            self._argmax and c in set(self._slip_cols.tolist())
            for c in range(max(probe.size, 1))
        )
        if io_binding:
            self._out = np.empty_like(probe)
            self._binding = self._session.io_binding()
            # ortvalue_from_numpy shares the numpy buffer on the CPU: rewriting
            # self._input in place is what the next call sees, and the score lands
            # in self._out without an allocation.
            self._in_ort = ort.OrtValue.ortvalue_from_numpy(self._input)
            self._out_ort = ort.OrtValue.ortvalue_from_numpy(self._out)
            self._binding.bind_ortvalue_input(inp.name, self._in_ort)
            self._binding.bind_ortvalue_output(d.output, self._out_ort)
            # Kept referenced: the binding reads and writes these buffers in place.
            self._state_ort = []
            for s, h_in, h_out in zip(m.state, self._h_in, self._h_out, strict=True):
                v_in = ort.OrtValue.ortvalue_from_numpy(h_in)
                v_out = ort.OrtValue.ortvalue_from_numpy(h_out)
                self._binding.bind_ortvalue_input(s.input, v_in)
                self._binding.bind_ortvalue_output(s.output, v_out)
                self._state_ort += [v_in, v_out]
            if self._prep is not None:
                part = ort.OrtValue.ortvalue_from_numpy(self._partial)
                self._state_ort.append(part)
                self._binding.bind_ortvalue_input(self._prep_name, part)
                self._prep_binding = self._prep.io_binding()
                self._prep_binding.bind_ortvalue_input(inp.name, self._in_ort)
                self._prep_binding.bind_ortvalue_output(self._prep_name, part)
        # The warm-up stops early once it has taken the bundle's load deadline: it
        # only primes allocations, and a slow graph must not hold the start for
        # warmup x its call time.
        stop = time.perf_counter() + bundle.deadline_s
        for _ in range(bundle.session_spec.warmup):
            if self._prep is not None:
                self._run_prepare()
            self._call()
            if time.perf_counter() > stop:
                break
        self._capacity = capacity
        self.reset()
        self._row0 = self._rows[0]
        self._window0 = self._windows[0]
        # Hop 1 (the BioTac force models: one-frame windows) takes _step_hop1, a
        # hand-written copy of step's good-frame path: step's fixed work (~3 us)
        # is as long as a one-node graph's call, so the target (loop <=
        # 2x the bare call) needs the branches and the frame's own finiteness test
        # it leaves out (docs/deploy.md, "Fewer nodes, less loop work"). Only when
        # every op keeps a NaN or infinity non-finite (Op's keeps_nonfinite) and
        # every frame completes a window (hop 1) does testing the graph input
        # alone catch a bad frame.
        if (
            self._hop == 1
            and not self.nan_is_missing
            and self._binding is not None
            and not self._state  # step carries and resets the recurrent state
            and self._prep is None
            and all(hasattr(op, "keeps_nonfinite") for op in self._ops)
        ):
            self.step = self._step_hop1  # type: ignore[method-assign]
        if self._prep is not None:
            self.step = self._step_prepared  # type: ignore[method-assign]
            # the prepared check lives in this bundle's _decide only: other bundles'
            # per-frame path (_step_hop1 included) gains nothing
            self._decide = self._decide_prepared  # type: ignore[method-assign]

    def reset(self) -> None:
        """Forget the window, the debounce state, the records and any op state (e.g. a baseline)."""
        for op in self._ops:
            getattr(op, "reset", lambda: None)()
        self._ring[...] = 0.0
        self._pos = 0
        self.n_frames = 0
        self._run = 0
        self._n = 0
        self._prev_ts = math.nan
        # 1-based count of the frame that completes the current stream's first
        # window: the window until a gap restarts the stream (*Stream state*); the
        # hop grid runs from it.
        self._first = self._w
        # _step_hop1's ops all keep non-finite values (re-tested until a stateful
        # op such as baseline_first is complete).
        self._folded = False
        # Windows completed by frames before this (1-based) count hold a flagged
        # frame or span a gap and are skipped.
        self._clean_from = 0
        self.n_bad = 0
        self.last_bad: str | None = None
        self._bad_frame: list[int] = []
        self._bad_reason: list[str] = []
        self._skipped = 0
        self._nonfinite_windows = 0
        self._gaps = 0
        for h in self._h_in:
            h.fill(0)
        self._state_resets = 0
        self._prepared_for = -1
        self._prep_late = 0
        self._n_prep = 0
        cap = self._capacity
        self._prep_lat = np.zeros(cap if self._prep is not None else 0, dtype=np.int64)
        self._frame = np.zeros(cap, dtype=np.int64)
        self._ts = np.zeros(cap)
        self._score = np.zeros(cap)
        self._slip = np.zeros(cap, dtype=bool)
        self._decl = np.zeros(cap, dtype=bool)
        self._lat = np.zeros(cap, dtype=np.int64)
        self._klass = np.zeros(cap, dtype=np.int64)

    def window(self) -> NDArray[np.float64]:
        """A copy of the latest ``window`` frames, oldest first (zeros before they arrive)."""
        return self._windows[self._pos].copy()

    def _zero_state(self) -> None:
        """Set a recurrent state back to zeros (counted; nothing without state)."""
        if self._state:
            for h in self._h_in:
                h.fill(0)
            self._state_resets += 1

    def _run_prepare(self) -> None:
        """The prepare graph on the graph input as written (its output: the buffer
        the main graph reads)."""
        assert self._prep is not None
        if self._prep_binding is not None:
            self._prep.run_with_iobinding(self._prep_binding)
        else:
            out = self._prep.run([self._prep_name], self._prep_feed)[0]
            np.copyto(self._partial, out)

    def _step_prepared(
        self,
        values: ArrayLike,
        timestamp: float | None = None,
        arrival_ns: int | None = None,
    ) -> bool | None:
        """:meth:`step`, then the prepare graph when the next frame completes a
        window due for a decision (module docstring, *Prepared decisions*)."""
        t0 = _clock() if arrival_ns is None else arrival_ns
        out = StreamLoop.step(self, values, timestamp, t0)
        nxt = self.n_frames + 1
        w = self._w
        if nxt >= w and not (nxt - w) % self._hop and nxt >= self._clean_from:
            # this frame's window, as the main graph would read it (no
            # preprocessing: the manifest refuses prepare with steps)
            self._input_view[...] = self._windows[self._pos]
            self._run_prepare()
            self._prepared_for = nxt
            i = self._n_prep
            if i == len(self._prep_lat):
                self._prep_lat = np.concatenate([self._prep_lat, self._prep_lat])
            self._prep_lat[i] = _clock() - t0
            self._n_prep = i + 1
        return out

    def _decide_prepared(
        self, seen: int, timestamp: float | None, t0: int
    ) -> bool | None:
        """:meth:`_decide` for a bundle with a prepare graph: prepare late when the
        frame before did not (module docstring, *Prepared decisions*), then decide."""
        if self._prepared_for != seen:
            self._prepare_late()
        self._prepared_for = -1
        return StreamLoop._decide(self, seen, timestamp, t0)

    def _prepare_late(self) -> None:
        """The prepare graph on the previous frame's window, the input restored after."""
        np.copyto(self._late_input, self._input)
        self._input_view[...] = self._windows[(self._pos - 1) % self._w]
        self._run_prepare()
        np.copyto(self._input, self._late_input)
        self._prep_late += 1

    def _call(self) -> NDArray[Any]:
        if self._binding is None:
            out: NDArray[Any] = self._session.run(self._out_names, self._feed)[0]
            return out
        self._session.run_with_iobinding(self._binding)
        return self._out

    def _grow(self) -> None:
        for name in ("_frame", "_ts", "_score", "_slip", "_decl", "_lat", "_klass"):
            old = getattr(self, name)
            new = np.zeros(2 * len(old), dtype=old.dtype)
            new[: len(old)] = old
            setattr(self, name, new)

    def step(
        self,
        values: ArrayLike,
        timestamp: float | None = None,
        arrival_ns: int | None = None,
    ) -> bool | None:
        """Push one frame; decide when a window is complete, valid and the hop is due.

        Never raises on a bad frame: it is flagged (:attr:`last_bad`, counted in
        :attr:`n_bad` and the result) and the windows holding it are skipped
        (module docstring, *Bad frames*).

        Parameters
        ----------
        values : array_like of shape frame.shape
            The frame, in the manifest's channel order (real numbers).
        timestamp : float, optional
            Its sensor time, s (recorded with the decision, and checked: finite,
            after the previous frame's, gaps noted). None skips the time checks.
        arrival_ns : int, optional
            :func:`time.perf_counter_ns` at arrival; now when omitted.

        Returns
        -------
        bool or None
            Whether slip is declared (debounced) on this frame; None when no
            decision was made (window still filling, between hops, or a skipped
            window).
        """
        t0 = time.perf_counter_ns() if arrival_ns is None else arrival_ns
        w = self._w
        p = self._pos
        seen = self.n_frames = self.n_frames + 1
        bad: str | None = None
        if (
            type(values) is np.ndarray
            and values.shape == self._shape
            and values.dtype.kind in "fiu"
        ):
            rows = self._rows
            row = rows[p]
            row[...] = values
            if w > 1:  # the copy that keeps every window contiguous; none for one frame
                rows[p + w][...] = values  # a row view: ~40 ns less than ring[p + w]
            self._check(row, out=self._finite)
            if self._finite.tobytes() != self._frame_ok:
                bad = "nonfinite"
        else:
            bad = self._store_odd(values, p)
        if timestamp is not None:
            try:
                dt = timestamp - self._prev_ts
                in_step = 0.0 < dt <= self._max_dt
            except TypeError:  # not a number; named by the slow path
                dt, in_step = math.nan, False
            if in_step:
                self._prev_ts = timestamp
            else:
                bad = self._check_time(timestamp, dt, seen, bad)
        self.last_bad = bad
        if bad is not None:
            self._flag(seen, bad)
        p += 1
        if p == w:
            p = 0
        self._pos = p
        first = self._first
        if seen < first or (seen - first) % self._hop:
            return None
        if seen < self._clean_from:
            self._skipped += 1
            self._run = 0
            return None
        x = self._windows[p]
        for op in self._ops:
            x = op(x)
        self._input_view[...] = x
        self._check(self._input_flat, out=self._input_finite)
        if self._input_finite.tobytes() != self._input_ok:
            # A finite frame can still overflow float32 after preprocessing (or an
            # op can make a NaN); a graph fed an infinity can return a finite but
            # meaningless score (exp(-inf) = 0 in an RBF kernel), so skip it here.
            self._skip_nonfinite()
            return None
        return self._decide(seen, timestamp, t0)

    def _decide(self, seen: int, timestamp: float | None, t0: int) -> bool | None:
        """Call the graph on the written input, apply the rule and debounce, record.

        ``seen`` is the 1-based count of frames pushed, ``t0`` the arrival, ns.
        Returns as :meth:`step` does.
        """
        if self._binding is None:
            score, *states = self._session.run(self._out_names, self._feed)
            for (_, h_out), h in zip(self._h_pairs, states, strict=True):
                np.copyto(h_out, h)
        else:
            self._session.run_with_iobinding(self._binding)
            score = self._out
        if self._argmax:
            # argmax returns the first NaN when there is one: a finite top entry
            # means every entry is finite.
            cls = int(score.argmax())
            top = score.item(cls)
            if not math.isfinite(top):
                self._skip_nonfinite()
                return None
            slip = self._is_slip[cls]
            # The score: the largest slip-class entry (the top one when slip; the
            # fancy-indexed max costs ~1.5 us, so only when it is not).
            if self._one_slip_col:
                s = score.item(self._col)
            else:
                s = top if slip else float(score.flat[self._slip_cols].max())
        else:
            # .item, not .flat[...]: a flatiter object is ~2.6 KB allocated per call
            s = score.item(self._col)
            if not math.isfinite(s):
                # NaN compares False with any threshold: scoring it would read as a
                # silent "no slip". An overflow inside the graph is skipped instead.
                self._skip_nonfinite()
                return None
            above = s > self._thr if self._strict else s >= self._thr
            slip = above == self._slip_above
            cls = int(above) if self._has_classes else -1
        for h_in, h_out in self._h_pairs:  # the next frame's state (none: no loop)
            np.copyto(h_in, h_out)
        run = self._run = self._run + 1 if slip else 0
        declared = run >= self._k
        self._record(
            seen, timestamp, s, slip, cls, declared, time.perf_counter_ns() - t0
        )
        return declared

    def _record(
        self,
        seen: int,
        timestamp: float | None,
        s: float,
        slip: bool,
        cls: int,
        declared: bool,
        latency_ns: int,
    ) -> None:
        """Store one decision (after the latency clock stopped) and call ``on_decision``."""
        i = self._n
        if i == len(self._lat):
            self._grow()
        ts = math.nan if timestamp is None else timestamp
        self._frame[i] = seen - 1
        self._ts[i] = ts
        self._score[i] = s
        self._slip[i] = slip
        self._klass[i] = cls
        self._decl[i] = declared
        self._lat[i] = latency_ns
        self._n = i + 1
        if self.on_decision is not None:
            self.on_decision(seen - 1, ts, s, cls, slip, declared, latency_ns)

    def _step_hop1(
        self,
        values: ArrayLike,
        timestamp: float | None = None,
        arrival_ns: int | None = None,
    ) -> bool | None:
        """:meth:`step` for hop 1, once the ops keep non-finite values.

        Chosen at construction (see ``__init__``); a good frame with an in-step
        timestamp that completes a clean window goes into the ring and, with the
        window, through the ops into the graph input, whose finiteness test
        stands for the frame's: the window's older frames were tested before, the
        ops keep a NaN or infinity non-finite, and so does the float32 cast. Only
        when the input is not finite is the frame tested, to tell a bad frame
        (flagged) from a float32 overflow (a skipped window). Anything else (not
        an ndarray of the frame's shape and a real dtype, no timestamp, the
        first, a faulty or a gap timestamp, a window still filling or to be
        skipped, a stateful op not yet complete) takes :meth:`step` unchanged, so
        the results are :meth:`step`'s.
        """
        t0 = _clock() if arrival_ns is None else arrival_ns
        if (
            type(values) is not _ndarray
            or values.shape != self._shape
            or values.dtype.kind not in "fiu"
            or timestamp is None
            or not (self._folded or self._fold_ready())
        ):
            return StreamLoop.step(self, values, timestamp, t0)
        try:
            dt = timestamp - self._prev_ts
            in_step = 0.0 < dt <= self._max_dt
        except TypeError:  # not a number; named by step
            in_step = False
        if not in_step:
            return StreamLoop.step(self, values, timestamp, t0)
        seen = self.n_frames + 1
        w = self._w
        # Window still filling, or one that holds a flagged frame or spans a gap
        # (skip_gaps): no graph input to test, so step tests the frame. (Neither
        # happens with one-frame windows: a flagged frame or a gap skips only its
        # own window, and this frame's timestamp is in step.)
        if w > 1 and (seen < w or seen < self._clean_from):
            return StreamLoop.step(self, values, timestamp, t0)
        self._prev_ts = timestamp
        self.n_frames = seen
        self.last_bad = None
        if w == 1:
            row = self._row0
            x = self._window0
        else:
            p = self._pos
            row = self._rows[p]
            self._rows[p + w][...] = values
            p += 1
            if p == w:
                p = 0
            self._pos = p
            x = self._windows[p]
        row[...] = values
        for op in self._ops:
            x = op(x)
        self._input_view[...] = x
        np.isfinite(self._input_flat, out=self._input_finite)
        if self._input_finite.tobytes() != self._input_ok:
            self._nonfinite_hop1(seen, row)
            return None
        if self._argmax:
            return self._decide(seen, timestamp, t0)
        # _decide's threshold rule, inline (one call fewer on the force models).
        self._session.run_with_iobinding(self._binding)
        s = self._out.item(self._col)
        if not math.isfinite(s):
            self._skip_nonfinite()
            return None
        above = s > self._thr if self._strict else s >= self._thr
        slip = above == self._slip_above
        run = self._run = self._run + 1 if slip else 0
        declared = run >= self._k
        t1 = _clock()
        self._record(
            seen,
            timestamp,
            s,
            slip,
            int(above) if self._has_classes else -1,
            declared,
            t1 - t0,
        )
        return declared

    def _fold_ready(self) -> bool:
        """Whether every op keeps non-finite values now (remembered once true, until reset)."""
        self._folded = all(op.keeps_nonfinite for op in self._ops)  # type: ignore[attr-defined]
        return self._folded

    def _nonfinite_hop1(self, seen: int, row: NDArray[np.float64]) -> None:
        """:meth:`_step_hop1`'s input is not finite: flag a bad frame, else skip the window.

        ``row`` is the new frame's ring row. The window's older frames were all
        tested good (a window holding a flagged one is never computed), so the new
        frame is bad, or the input overflowed float32.
        """
        np.isfinite(row, out=self._finite)
        if self._finite.tobytes() != self._frame_ok:
            # What step does with a bad frame: flag it, skip this window.
            self.last_bad = "nonfinite"
            self._flag(seen, "nonfinite")
            self._skipped += 1
            self._run = 0
        else:
            self._skip_nonfinite()

    def _store_odd(self, values: Any, p: int) -> str | None:
        """Store a frame that is not an ndarray of the frame shape; name its fault.

        The slow path: a list (or other sequence) of the right shape and a real
        dtype is stored like an array; anything else is stored as NaN so no window
        holding it can look valid.
        """
        w, ring = self._w, self._ring
        try:
            arr = np.asarray(values)
        except (ValueError, TypeError):  # ragged nesting
            arr = None
        if arr is None:
            bad = "shape"
        elif arr.dtype.kind not in "fiu":
            bad = "dtype"
        elif arr.shape != self._shape:
            bad = "shape"
        else:
            ring[p] = arr
            ring[p + w] = arr
            self._check(ring[p], out=self._finite)
            return "nonfinite" if self._finite.tobytes() != self._frame_ok else None
        ring[p] = math.nan
        ring[p + w] = math.nan
        return bad

    def _check_time(
        self, timestamp: float, dt: float, seen: int, bad: str | None
    ) -> str | None:
        """The slow path of the time check: first frame, a fault, or a gap."""
        if not (
            isinstance(timestamp, int | float | np.integer | np.floating)
            and math.isfinite(timestamp)
        ):
            return bad or "timestamp"
        prev = self._prev_ts
        self._prev_ts = timestamp
        if math.isnan(prev):  # the first timed frame
            return bad
        if dt == 0.0:
            return bad or "duplicate_time"
        if dt < 0.0:
            return bad or "time_order"
        self._gaps += 1
        self._zero_state()
        if self._restart_on_gap and dt > self._restart_dt:
            self._restart(seen)
        elif self._skip_gaps:
            # Windows holding the frames on both sides of the gap: the ones ending
            # here and at the next window - 2 frames.
            self._clean_from = max(self._clean_from, seen + self._w - 1)
        return bad

    def _restart(self, seen: int) -> None:
        """A gap in a bundle with stream state: frame ``seen`` (1-based) starts a new
        recording (module docstring, *Stream state*)."""
        for op in self._stream_ops:
            op.reset()  # type: ignore[attr-defined]
        self._first = seen - 1 + self._w
        # _step_hop1 hands the windows before it to step, which does not score them
        self._clean_from = max(self._clean_from, self._first)
        self._folded = False  # an op's keeps_nonfinite may be False again

    def _skip_nonfinite(self) -> None:
        self._skipped += 1
        self._nonfinite_windows += 1
        self._run = 0
        self._zero_state()

    def _flag(self, seen: int, reason: str) -> None:
        self._zero_state()
        self.n_bad += 1
        self._bad_frame.append(seen - 1)
        self._bad_reason.append(reason)
        # Windows ending at this frame and the next window - 1 frames hold it.
        self._clean_from = max(self._clean_from, seen + self._w)

    def run(self, source: Iterable[Frame]) -> LoopResult:
        """Push every frame of a source (replay or UDP) and return the result.

        Raises
        ------
        BundleError
            onnxruntime failed on a frame (named, with the graph's file).
        """
        step = self.step
        try:
            for frame in source:
                step(frame.values, frame.timestamp, frame.arrival_ns)
        except ORT_ERRORS as exc:
            raise BundleError(
                str(self.bundle.path / MODEL_FILE),
                None,
                f"onnxruntime failed on stream frame {self.n_frames - 1}: "
                + " ".join(str(exc).split()),
            ) from None
        return self.result()

    def result(self) -> LoopResult:
        """The decisions so far (copies)."""
        n = self._n
        m = self.bundle.manifest
        return LoopResult(
            frame=self._frame[:n].copy(),
            timestamp=self._ts[:n].copy(),
            score=self._score[:n].copy(),
            slip=self._slip[:n].copy(),
            declared=self._decl[:n].copy(),
            latency_ns=self._lat[:n].copy(),
            n_frames=self.n_frames,
            name=m.name,
            debounce_k=m.debounce_k,
            budget=m.budget,
            bad_frame=np.array(self._bad_frame, dtype=np.int64),
            bad_reason=tuple(self._bad_reason),
            skipped_windows=self._skipped,
            nonfinite_windows=self._nonfinite_windows,
            gaps=self._gaps,
            klass=self._klass[:n].copy(),
            classes=m.decision.classes,
            slip_classes=m.decision.slip_classes,
            state_resets=self._state_resets,
            prepare_latency_ns=self._prep_lat[: self._n_prep].copy(),
            prepare_late=self._prep_late,
            has_prepare=self._prep is not None,
        )


__all__ = [
    "BAD_REASONS",
    "NAN_IS_MISSING_STREAMS",
    "RESTART_GAP_PERIODS",
    "LoopResult",
    "StreamLoop",
    "latency_summary",
]
