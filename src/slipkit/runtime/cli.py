"""``slipkit-run``: run a bundle's loop on recorded or streamed frames and check its latency budget.

Usage::

    slipkit-run exports/tactip_svm                       # the bundle's replay.npz
    slipkit-run exports/tactip_svm --replay frames.npz --check --json out.json
    slipkit-run exports/tactip_svm --check --no-pace    # frames back to back (understates)
    slipkit-run exports/tactip_svm --udp 127.0.0.1:9000 --frames 1000
    slipkit-run exports/tactip_svm --udp 127.0.0.1:9000 --wait 0 --timeout 5
    slipkit-run exports/tactip_svm --choose-session      # measure session options
    slipkit-run exports/tactip_svm --key ~/lab.key       # refuse an unsigned or edited bundle
    slipkit-run exports/tactip_svm --card                # print its model card (MODEL_CARD.md)
    slipkit-run exports/sliptack --cpus 1 --realtime     # affinity, SCHED_FIFO, GC, threads
    slipkit-run exports/tactip_svm --udp 0.0.0.0:9000 --send 192.168.1.20:9100 --jsonl
    slipkit-run exports/tactip_svm --lsl TacTip --lsl-out SlipDecisions
    slipkit-run --stream index=bundles/biotac@udp:0.0.0.0:9001 \
                --stream palm=bundles/fsr@udp:0.0.0.0:9002 --send 127.0.0.1:9100
    slipkit-run --stream ... --pace --realtime --cpus 1 --spin-us 450  # spin before frames
    slipkit-run exports/fsr --udp 0.0.0.0:9000 --cpus 1 --busy-poll   # never sleep: one core

With ``--stream`` (repeated) one process serves a whole hand: each bundle on its own
input, reported per stream (:mod:`slipkit.runtime.hand`).

``--check`` judges latency by the latency rule (:mod:`slipkit.runtime.budget`, the same
as ``slipkit compare``'s): replays paced at the sensor's rate by default (``--no-pace``:
back to back, said in the verdict), the median of 5 block p99s of the decision and
prepare frames, ``within`` / ``borderline`` (passes) / ``over`` (fails).

Exit status: 0 success; 1 ``--check`` failed (p99 over the rule's margin of the
manifest's budget, or no decision was made; with ``--stream``, on any stream), ``--udp`` / ``--lsl`` and no
frame arrived within ``--wait``, or a stream of a hand failed; 2 a bad bundle, replay file or argument: one line on stderr,
``slipkit-run: error: ...``, naming the file and field or the option. Every deliberate
error is a :class:`~slipkit.errors.SlipkitError`; any other exception is a bug and
keeps its traceback. argparse, not Hydra: a gripper PC has numpy and onnxruntime only.
"""

from __future__ import annotations

import argparse
import json
import re
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from slipkit._files import check_out_file, read_json_object, write_out_file
from slipkit.errors import SlipkitError
from slipkit.runtime.budget import (
    PACED_MIN_FRAMES,
    PACED_S,
    STATISTIC,
    UNPACED_NOTE,
    paced_frames,
    pacing_spins,
)
from slipkit.runtime.bundle import (
    CARD_FILE,
    DEFAULT_DEADLINE_S,
    MAX_DEADLINE_S,
    Bundle,
    load_bundle,
    read_key,
)
from slipkit.runtime.errors import BundleError, FrameError, OptionError
from slipkit.runtime.hand import (
    MAX_SPIN_US,
    MODES,
    ReplayFeed,
    check_spin_us,
    parse_stream,
    run_hand_cli,
)
from slipkit.runtime.loop import StreamLoop
from slipkit.runtime.modules import heavy_modules_loaded
from slipkit.runtime.realtime import (
    RealtimeOptions,
    apply_realtime,
    frozen_gc,
    options_from_text,
    pinned_session,
)
from slipkit.runtime.sinks import Fanout, JsonlSink, UdpSink, parse_address
from slipkit.runtime.sources import (
    DEFAULT_WAIT_S,
    MAX_RESYNC_AFTER,
    MAX_TIMEOUT_S,
    RESYNC_AFTER,
    ReplaySource,
    UdpSource,
    load_replay,
)
from slipkit.runtime.tuning import MAX_ROUNDS, choose_session

#: Characters ``--card`` does not print as they are: C0 / C1 controls but tab and newline.
_CONTROL = re.compile("[\x00-\x08\x0b-\x1f\x7f-\x9f]")

#: ``format`` of the summary ``--json`` writes: an existing file at ``--json`` is replaced
#: only when it is such a summary (:func:`is_summary`)
SUMMARY_FORMAT = "slipkit-run-summary"


def is_summary(path: Path) -> bool:
    """Whether ``path`` holds a summary ``--json`` wrote (and may write again).

    One carrying ``"format": "slipkit-run-summary"``, or one written before the
    marker: a single run's (``bundle`` with ``latency_ms`` and ``budget_ms``),
    ``--choose-session``'s (``bundle`` with ``session_candidates``) or a hand's
    (``hand`` with ``streams``).
    """
    obj = read_json_object(path)
    if obj is None:
        return False
    if "format" in obj:
        return obj["format"] == SUMMARY_FORMAT
    return (
        ("bundle" in obj and {"latency_ms", "budget_ms"} <= obj.keys())
        or ("bundle" in obj and "session_candidates" in obj)
        or ("hand" in obj and "streams" in obj)
    )


def _inputs(args: argparse.Namespace) -> dict[str, Path | str | None]:
    """The files and folders this run reads, by option: ``--json`` is none of them."""
    inputs: dict[str, Path | str | None] = {
        "BUNDLE": args.bundle,
        "--replay": args.replay,
    }
    for text in args.stream or []:
        b = parse_stream(text)
        inputs[f"--stream {b.name}"] = b.bundle
        if b.kind == "replay":
            inputs[f"--stream {b.name} replay"] = b.target
    return inputs


def _json_out(args: argparse.Namespace) -> dict[str, Any]:
    """The keyword arguments of the ``--json`` checks (``slipkit._files``)."""
    return {
        "option": "--json",
        "inputs": _inputs(args),
        "is_own": is_summary,
        "what": "a slipkit-run summary",
    }


class _Parser(argparse.ArgumentParser):
    """argparse with its usage errors as one line (``slipkit-run: error: ...``), exit 2."""

    def error(self, message: str) -> Any:  # argparse's hook; never returns
        print(f"{self.prog}: error: {' '.join(message.split())}", file=sys.stderr)
        raise SystemExit(2)


def _parser() -> argparse.ArgumentParser:
    p = _Parser(
        prog="slipkit-run",
        description="Run a slipkit ONNX bundle's decision loop frame by frame and report "
        "per-frame latency (frame arrival -> decision) against the bundle's budget.",
    )
    p.add_argument(
        "bundle",
        type=Path,
        nargs="?",
        help="bundle folder (model.onnx + manifest.json); omit with --stream",
    )
    p.add_argument(
        "--stream",
        action="append",
        metavar="NAME=BUNDLE[@SOURCE]",
        help="a whole hand: repeat to run several bundles in one process, each on its "
        "own input; SOURCE is replay:FILE, udp:HOST:PORT or lsl:STREAM_NAME (default: "
        "the bundle's replay.npz); reported per stream (docs/deploy.md)",
    )
    p.add_argument(
        "--hand-mode",
        choices=MODES,
        default="loop",
        help="--stream: serve the streams round-robin from one thread (loop, default) "
        "or one thread per stream (threads)",
    )
    p.add_argument(
        "--pace",
        action=argparse.BooleanOptionalAction,
        default=None,
        help="hand replayed frames over at their own timestamps' rate (wall clock), as "
        "the sensor would, instead of as fast as the loop takes them (a paced BUNDLE "
        f"replay plays at most max({PACED_MIN_FRAMES} frames, {PACED_S:g} s) unless "
        "--frames says; docs/deploy.md); default: a BUNDLE replay is paced with "
        "--check, else not; --stream replays are not",
    )
    src = p.add_mutually_exclusive_group()
    src.add_argument(
        "--replay",
        type=Path,
        help="frames to replay: .npz (frames, timestamps) or .npy; default: the bundle's replay.npz",
    )
    src.add_argument(
        "--udp",
        metavar="HOST:PORT",
        help="receive frames as UDP datagrams (docs/deploy.md); port 0 picks a free port, printed on stderr",
    )
    src.add_argument(
        "--lsl",
        metavar="STREAM_NAME",
        help="receive frames from the Lab Streaming Layer stream of this name "
        "(needs pip install 'slipkit[lsl]')",
    )
    p.add_argument(
        "--frames",
        type=int,
        metavar="N",
        help="stop after N frames (replay: the first N)",
    )
    p.add_argument(
        "--timeout",
        type=float,
        default=2.0,
        metavar="S",
        help="UDP: after the first frame, stop when no frame has been accepted for S "
        f"seconds, wall clock (default 2; at most {MAX_TIMEOUT_S:g})",
    )
    p.add_argument(
        "--wait",
        type=float,
        default=DEFAULT_WAIT_S,
        metavar="S",
        help="UDP: stop (exit 1) when no frame has been accepted S seconds after "
        f"listening starts; 0 waits forever (default {DEFAULT_WAIT_S:g}; at most "
        f"{MAX_TIMEOUT_S:g})",
    )
    p.add_argument(
        "--resync-after",
        type=int,
        default=RESYNC_AFTER,
        metavar="N",
        help="UDP: after N consecutive out-of-order frame indices, accept the next one "
        f"as a new sequence (a restarted sender; default {RESYNC_AFTER})",
    )
    p.add_argument(
        "--load-deadline",
        type=float,
        default=DEFAULT_DEADLINE_S,
        metavar="S",
        help="seconds the graph's first call may take when the bundle loads "
        f"(default {DEFAULT_DEADLINE_S:g}; at most {MAX_DEADLINE_S:g})",
    )
    p.add_argument(
        "--key",
        type=Path,
        metavar="FILE",
        help="the lab's signing key (any bytes, kept outside the bundle): refuse a "
        "bundle whose manifest.hmac is missing or is not the HMAC-SHA256 of its "
        "manifest.json under this key (docs/deploy.md, Signed bundles)",
    )
    p.add_argument(
        "--send",
        metavar="HOST:PORT",
        help="send every decision as it is made as a UDP datagram (docs/deploy.md, "
        "Decisions out; non-blocking: a failed send is counted, never waited on)",
    )
    p.add_argument(
        "--lsl-out",
        metavar="NAME",
        help="push every decision as it is made to an LSL outlet of this name "
        "(8 channels, docs/deploy.md; needs pip install 'slipkit[lsl]')",
    )
    p.add_argument(
        "--jsonl",
        action="store_true",
        help="print every decision as it is made as one JSON line on stdout (flushed "
        "per line), before the summary",
    )
    p.add_argument(
        "--check",
        action="store_true",
        help="exit 1 when the latency rule judges the p99 over the manifest's "
        "budget_ms.p99 (within and borderline pass); paces a replay unless --no-pace",
    )
    p.add_argument(
        "--json",
        type=Path,
        metavar="OUT",
        help="write the summary as JSON (atomically); an existing OUT is replaced only "
        "when it is such a summary",
    )
    p.add_argument(
        "--io-binding",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="call the graph through a preallocated onnxruntime IOBinding (default; "
        "measured faster, docs/deploy.md) or, with --no-io-binding, session.run",
    )
    p.add_argument(
        "--choose-session",
        action="store_true",
        help="measure session option sets on the replay frames, print them fastest first, and exit",
    )
    p.add_argument(
        "--card",
        action="store_true",
        help="print the bundle's model card (MODEL_CARD.md: training data, licence, "
        "held-out metrics, operating point, latency) once the bundle has loaded and "
        "passed its checks, and exit",
    )
    p.add_argument(
        "--rounds",
        type=int,
        default=3,
        help=f"--choose-session: round-robin passes (default 3; 1 to {MAX_ROUNDS})",
    )
    p.add_argument(
        "--report-modules",
        action="store_true",
        help="print (and add to --json) which heavy libraries (torch, sklearn, hydra, pandas, ...) were imported",
    )
    # Real-time options (slipkit.runtime.realtime; docs/deploy.md, Deadlines under load)
    rt = p.add_argument_group(
        "real-time options (docs/deploy.md, Deadlines under load)"
    )
    rt.add_argument(
        "--cpus",
        metavar="LIST",
        help="pin the process to these cores (os.sched_setaffinity), e.g. 1 or 0,2-3",
    )
    rt.add_argument(
        "--priority",
        default="normal",
        metavar="KIND[:N]",
        help="normal (default), nice[:N] (os.nice, N in -20..19, default -10) or "
        "fifo[:N] (SCHED_FIFO, N in 1..99, default 10); one line and normal "
        "priority when not permitted",
    )
    rt.add_argument(
        "--freeze-gc",
        action="store_true",
        help="collect, freeze and disable the garbage collector while the loop runs",
    )
    rt.add_argument(
        "--pin-threads",
        action="store_true",
        help="onnxruntime with one intra-op and one inter-op thread (overrides the "
        "manifest's session)",
    )
    rt.add_argument(
        "--spin",
        action=argparse.BooleanOptionalAction,
        default=False,
        help="with --pin-threads: session.intra_op.allow_spinning (default off)",
    )
    rt.add_argument(
        "--realtime",
        action="store_true",
        help="shorthand for --priority fifo --freeze-gc --pin-threads (add --cpus)",
    )
    rt.add_argument(
        "--busy-poll",
        action="store_true",
        help="never sleep between frames: spin to each paced replay frame's due time "
        "and poll UDP/LSL inputs without blocking; burns one core (pair it with "
        "--cpus); not part of --realtime: under --priority fifo the kernel's RT "
        "throttling stalls a spinning loop 50 ms every second (docs/deploy.md)",
    )
    rt.add_argument(
        "--spin-us",
        type=float,
        default=0.0,
        metavar="N",
        help="paced replays: sleep until N us before each replay frame is due, "
        f"then spin the rest (0 to {MAX_SPIN_US:g}; default 0: sleep the whole wait)",
    )
    return p


def _fmt(ms: float) -> str:
    return f"{ms:.4f}"


def _summary_lines(summary: dict[str, Any], source: str) -> list[str]:
    s = summary
    first = s["first_declared_s"]
    lines = [
        f"{s['bundle']}: {s['frames']} frames from {source}, {s['decisions']} decisions, "
        f"{s['slip_decisions']} slip, {s['declared']} declared (debounce k={s['debounce_k']})"
        + (f", first declared at {first:.4f} s" if first is not None else "")
    ]
    by_class = s.get("decisions_by_class")
    if by_class:
        slip = set(s.get("slip_classes") or ())
        lines.append(
            "decisions by class: "
            + ", ".join(
                f"{c}{'*' if c in slip else ''} {n}" for c, n in by_class.items()
            )
            + " (* slip class)"
        )
    reasons = ", ".join(f"{k} {v}" for k, v in s["bad_by_reason"].items() if v)
    lines.append(
        f"flagged: {s['bad_frames']} bad frames"
        + (f" ({reasons})" if reasons else "")
        + f", {s['gaps']} gaps, {s['skipped_windows']} windows skipped"
        + f" ({s['nonfinite_windows']} with a non-finite input or score)"
    )
    lat, budget = s["latency_ms"], s["budget_ms"]
    if lat is not None:
        lines.append(
            "latency arrival->decision (ms): "
            f"p50 {_fmt(lat['p50'])}  p99 {_fmt(lat['p99'])}  max {_fmt(lat['max'])}  mean {_fmt(lat['mean'])}"
        )
    prep = s.get("prepare")
    if prep is not None and prep["latency_ms"] is not None:
        pl = prep["latency_ms"]
        lines.append(
            f"prepare frames ({prep['calls']}, prepare.onnx on the frame before a "
            f"decision; {prep['late']} late) arrival->done (ms): p50 {_fmt(pl['p50'])}  "
            f"p99 {_fmt(pl['p99'])}  max {_fmt(pl['max'])}; {prep['over_budget']} over budget"
        )
    check = s.get("latency_check") or {}
    if s["within_budget"] is None or check.get("p99_ms") is None:
        verdict = "not measured (no decisions)"
    else:
        verdict = (
            f"p99 {_fmt(check['p99_ms'])} ms ({STATISTIC}"
            + (", decision and prepare frames" if prep is not None else "")
            + f") = {check['margin']:.2f} x: {check['status']}"
        )
    lines.append(
        f"budget: p99 <= {budget['p99']:g} ms (frame period {budget['frame_period']:g} ms): "
        f"{verdict}; {s['over_budget']} decisions over budget, {s['over_period']} over the frame period"
    )
    return lines


def _same_file(a: Path, b: Path) -> bool:
    try:
        return a.resolve() == b.resolve()
    except OSError:
        return False


def _replay_line(info: dict[str, Any]) -> str:
    """What the bundle's own replay holds (manifest ``training.replay``, schema 3)."""
    by_class = info.get("by_class") or {}
    classes = (
        " of classes " + ", ".join(f"{c} {n}" for c, n in by_class.items())
        if by_class
        else ""
    )
    held = (
        "held-out trials"
        if info.get("held_out")
        else "held_out: false (the model was refit on all data): checks parity and "
        "latency, not accuracy"
    )
    return f"replay: {info.get('trials')} trials{classes}; {held}"


def _address(text: str, option: str = "--udp") -> tuple[str, int]:
    return parse_address(text, option)


def _check_args(args: argparse.Namespace) -> None:
    """Range checks argparse's types do not make; each error names its option."""
    if args.stream:
        if args.bundle is not None:
            raise OptionError(
                "--stream",
                f"give either a BUNDLE or --stream, not both (got BUNDLE {str(args.bundle)!r})",
            )
        for option, given in (
            ("--replay", args.replay),
            ("--udp", args.udp),
            ("--lsl", args.lsl),
            ("--choose-session", args.choose_session or None),
            ("--card", args.card or None),
        ):
            if given is not None:
                raise OptionError(
                    option,
                    "is for a single BUNDLE; with --stream give NAME=BUNDLE@SOURCE",
                )
    elif args.bundle is None:
        raise OptionError("BUNDLE", "give a bundle folder, or one --stream per bundle")
    elif args.pace is not None and (args.udp or args.lsl or args.choose_session):
        live = "--udp" if args.udp else "--lsl" if args.lsl else None
        raise OptionError(
            "--pace" if args.pace else "--no-pace",
            f"paces replayed frames; {live} frames come at the sender's pace"
            if live
            else "--choose-session measures the options back to back",
        )
    # A BUNDLE replay is paced with --check unless --no-pace (the latency rule,
    # slipkit.runtime.budget); --stream replays only with --pace.
    unpaceable = args.udp is not None or args.lsl is not None or args.choose_session
    args.paced = (
        bool(args.pace)
        if args.stream or args.pace is not None
        else bool(args.check and not unpaceable)
    )
    args.pace = bool(args.pace) if args.stream else args.paced
    if args.frames is not None and args.frames < 1:
        raise OptionError("--frames", f"must be >= 1; got {args.frames}")
    if not 0 < args.timeout <= MAX_TIMEOUT_S:  # False for NaN too
        raise OptionError(
            "--timeout", f"must be in (0, {MAX_TIMEOUT_S:g}] s; got {args.timeout}"
        )
    if not 0 <= args.wait <= MAX_TIMEOUT_S:  # False for NaN too
        raise OptionError(
            "--wait",
            f"must be in [0, {MAX_TIMEOUT_S:g}] s (0: forever); got {args.wait}",
        )
    check_spin_us(args.spin_us)
    if args.spin_us and not args.paced:
        raise OptionError(
            "--spin-us",
            "spins before paced replay frames: give --pace (or --check on a replay)",
        )
    if args.busy_poll and args.stream and args.hand_mode == "threads":
        raise OptionError(
            "--busy-poll",
            "with --hand-mode threads every stream's thread would spin, each "
            "holding the GIL from the others; use --hand-mode loop (one thread polls "
            "every stream)",
        )
    if not 0 < args.load_deadline <= MAX_DEADLINE_S:
        raise OptionError(
            "--load-deadline",
            f"must be in (0, {MAX_DEADLINE_S:g}] s; got {args.load_deadline}",
        )
    if not 1 <= args.resync_after <= MAX_RESYNC_AFTER:
        raise OptionError(
            "--resync-after",
            f"must be in [1, {MAX_RESYNC_AFTER}]; got {args.resync_after}",
        )
    if not 1 <= args.rounds <= MAX_ROUNDS:
        raise OptionError(
            "--rounds", f"must be in [1, {MAX_ROUNDS}]; got {args.rounds}"
        )
    if args.udp is not None:
        _address(args.udp)
    if args.send is not None:
        parse_address(args.send, "--send", min_port=1)
    if args.json is not None:
        # Before any work: never an input, a user's own file, a FIFO or device, nor
        # a dataset's, run's or bundle's own files.
        check_out_file(args.json, **_json_out(args))
    args.key_bytes = None
    if args.key is not None:
        bundles: tuple[Path, ...] = (
            tuple(parse_stream(s).bundle for s in args.stream)
            if args.stream
            else (Path(str(args.bundle)),)
        )
        args.key_bytes = read_key(args.key, "--key", bundles=bundles)


def _replay(bundle: Bundle, path: Path | None) -> tuple[Any, Any, str]:
    f = bundle.manifest.frame
    path = path or bundle.replay_path
    if path is None:
        raise FrameError(
            str(bundle.path),
            "no frames: give --replay or --udp (the bundle has no replay.npz)",
        )
    frames, times = load_replay(path, f.shape, f.rate_hz)
    return frames, times, str(path)


def _run_source(
    args: argparse.Namespace, bundle: Bundle, loop: StreamLoop
) -> tuple[Any, str, dict[str, Any] | None, str | None]:
    """Run the loop on --udp or the replay: (result, source name, udp counts, replay line)."""
    udp: dict[str, Any] | None
    replay_line: str | None = None
    if args.udp is not None:
        host, port = _address(args.udp)
        try:
            source = UdpSource(
                host,
                port,
                bundle.manifest.frame.shape,
                max_frames=args.frames,
                timeout_s=args.timeout,
                wait_s=args.wait,
                resync_after=args.resync_after,
                busy_poll=args.busy_poll,
            )
        except OptionError as exc:
            raise OptionError("--udp", exc.problem) from None
        with source as src:
            print(
                f"listening on {src.where} (frames of {src.n_values} float32 values, format v1)",
                file=sys.stderr,
                flush=True,
            )
            result = loop.run(src)
        name = src.where
        udp = {
            "received": src.n_received,
            "rejected": src.n_rejected,
            "lost": src.n_lost,
            "resyncs": src.n_resyncs,
            "last_error": src.last_error,
            "ended": (
                "wait" if src.waited_out else "timeout" if src.timed_out else "frames"
            ),
        }
    elif args.lsl is not None:
        from slipkit.runtime.lsl import LslSource

        with LslSource(
            args.lsl,
            bundle.manifest.frame.shape,
            max_frames=args.frames,
            timeout_s=args.timeout,
            wait_s=args.wait,
            busy_poll=args.busy_poll,
        ) as lsrc:
            print(f"resolving {lsrc.where}", file=sys.stderr, flush=True)
            result = loop.run(lsrc)
        name = lsrc.where
        udp = {
            "kind": "lsl",
            "received": lsrc.n_received,
            "last_error": lsrc.last_error,
            "ended": (
                "wait" if lsrc.waited_out else "timeout" if lsrc.timed_out else "frames"
            ),
        }
    else:
        frames, times, name = _replay(bundle, args.replay)
        n = len(frames)
        if args.frames is not None:
            n = min(n, args.frames)
        elif args.paced:
            n = paced_frames(n, bundle.manifest.frame.rate_hz)
        frames, times = frames[:n], times[:n]
        # the latency rule spins for a fast sensor unless told how to wait
        args.spinning = bool(
            args.busy_poll
            or (not args.spin_us and pacing_spins(bundle.manifest.frame.rate_hz))
        )
        if args.paced:
            # the runtime's own pacing (the hand's replay feed): each frame handed over
            # at its timestamp, as the sensor would
            result = loop.run(
                ReplayFeed(
                    frames,
                    times,
                    pace=True,
                    busy_poll=args.spinning,
                    spin_ns=int(args.spin_us * 1000),
                )
            )
        else:
            result = loop.run(ReplaySource(frames, times))
        udp = None
        own = bundle.replay_path is not None and (
            args.replay is None or _same_file(args.replay, bundle.replay_path)
        )
        replay_info = bundle.manifest.training.get("replay")
        if own and isinstance(replay_info, dict):
            replay_line = _replay_line(replay_info)
    return result, name, udp, replay_line


def run(argv: Sequence[str] | None = None) -> int:
    """Parse arguments, run, print; return the exit status (see the module docstring)."""
    args = _parser().parse_args(argv)
    _check_args(args)
    out: dict[str, Any]
    if args.stream:
        # affinity, priority and the GC apply to the whole hand, --pin-threads to each
        # of its bundles' sessions
        rt_opts = _realtime_options(args)
        for note in apply_realtime(rt_opts).notes + _busy_poll_notes(args, rt_opts):
            print(f"slipkit-run: note: {note}", file=sys.stderr)
        with frozen_gc(rt_opts.freeze_gc):
            out, status = run_hand_cli(args, rt_opts)
        return _finish(args, out, status)
    rt_opts = _realtime_options(args)
    bundle = load_bundle(args.bundle, deadline_s=args.load_deadline, key=args.key_bytes)
    if args.card:
        card = bundle.card()
        if card is None:
            raise BundleError(
                str(Path(args.bundle) / CARD_FILE),
                None,
                "is missing: this bundle was written without a model card; "
                "re-export it with slipkit export to add one",
            )
        # control characters (a terminal's escape sequences) printed as \\xNN
        text = _CONTROL.sub(lambda m: f"\\x{ord(m.group()):02x}", card)
        sys.stdout.write(text if text.endswith("\n") else text + "\n")
        return 0
    if rt_opts.pin_threads:
        bundle = bundle.with_session(pinned_session(bundle.session_spec, rt_opts))
    if args.choose_session:
        frames, times, name = _replay(bundle, args.replay)
        n = len(frames) if args.frames is None else args.frames
        rows = choose_session(
            bundle,
            frames,
            times,
            rounds=args.rounds,
            max_frames=n,
            io_binding=args.io_binding,
        )
        if not rows:
            raise FrameError(
                name,
                f"{min(n, len(frames))} frames make no decision (the window is "
                f"{bundle.manifest.frame.window} frames): --choose-session has "
                "nothing to measure",
            )
        print(
            f"{bundle.manifest.name}: session options on {min(n, len(frames))} frames of {name}, {args.rounds} rounds (median), fastest first"
        )
        print(
            f"{'threads':>7} {'opt level':>9} {'spin':>5} {'p50 ms':>9} {'p99 ms':>9}"
        )
        for r in rows:
            ss = r["session"]
            print(
                f"{ss['intra_op_num_threads']:>7} {ss['graph_optimization_level']:>9} {ss['allow_spinning']!s:>5} {r['p50_ms']:>9.4f} {r['p99_ms']:>9.4f}"
            )
        print('manifest "session": ' + json.dumps(rows[0]["session"]))
        out = {"bundle": bundle.manifest.name, "session_candidates": rows}
        status = 0
    else:
        sinks: list[Any] = []
        udp_sink: UdpSink | None = None
        if args.send is not None:
            host, port = _address(args.send, "--send")
            try:
                udp_sink = UdpSink(host, port)
            except OptionError as exc:
                raise OptionError("--send", exc.problem) from None
            sinks.append(udp_sink)
        if args.jsonl:
            sinks.append(JsonlSink())
        lsl_hook = None
        if args.lsl_out is not None:
            from slipkit.runtime.lsl import LslOutlet

            lsl_hook = LslOutlet(args.lsl_out, [bundle.manifest.name]).hook(0)
            sinks.append(lsl_hook)
        hook = None if not sinks else sinks[0] if len(sinks) == 1 else Fanout(*sinks)
        try:
            loop = StreamLoop(bundle, io_binding=args.io_binding, on_decision=hook)
            rt_state = apply_realtime(rt_opts)
            for note in rt_state.notes + _busy_poll_notes(args, rt_opts):
                print(f"slipkit-run: note: {note}", file=sys.stderr)
            with frozen_gc(rt_opts.freeze_gc):
                result, name, udp, replay_line = _run_source(args, bundle, loop)
        finally:
            if udp_sink is not None:
                udp_sink.close()
        replayed = args.udp is None and args.lsl is None
        out = result.summary(paced=args.paced if replayed else None)
        out["source"] = name
        out["paced"] = args.paced if replayed else None
        if udp_sink is not None:
            out["send"] = {
                "to": args.send,
                "sent": udp_sink.n_sent,
                "errors": udp_sink.n_errors,
                "last_error": udp_sink.last_error,
            }
        out["io_binding"] = bool(args.io_binding)
        out["session"] = bundle.session_spec.to_json()
        if rt_opts.any:
            out["realtime"] = {
                **rt_opts.to_json(),
                "applied": rt_state.applied,
                "notes": rt_state.notes,
            }
        for line in _summary_lines(out, Path(name).name if udp is None else name):
            print(line)
        if udp is None and replay_line is not None:
            print(replay_line)
        if replayed:
            print(
                f"paced: {out['frames']} frames at their timestamps ("
                f"{bundle.manifest.frame.rate_hz:g} Hz"
                + (", spinning to each" if getattr(args, "spinning", False) else "")
                + ")"
                if args.paced
                else UNPACED_NOTE
            )
        if lsl_hook is not None:
            out["lsl_out"] = {"name": args.lsl_out, "pushed": lsl_hook.n_pushed}
            print(
                f"lsl-out: {lsl_hook.n_pushed} decisions pushed to LSL stream {args.lsl_out!r}"
            )
        lsl = udp if udp is not None and udp.pop("kind", None) == "lsl" else None
        if lsl is not None:
            out["lsl"] = lsl
            udp = None
            print(
                f"lsl: {lsl['received']} received"
                + (f" (last error: {lsl['last_error']})" if lsl["last_error"] else "")
            )
        if udp is not None:
            out["udp"] = udp
            print(
                f"udp: {udp['received']} received, {udp['rejected']} rejected, "
                f"{udp['lost']} lost, {udp['resyncs']} resyncs"
                + (
                    f" (last rejected: {udp['last_error']})"
                    if udp["last_error"]
                    else ""
                )
            )
        if udp_sink is not None:
            print(
                f"send: {udp_sink.n_sent} decisions sent to {args.send}, "
                f"{udp_sink.n_errors} send errors"
                + (f" (last: {udp_sink.last_error})" if udp_sink.last_error else "")
            )
        status = 1 if args.check and not out["within_budget"] else 0
        if udp is not None and udp["ended"] == "wait":
            # The sensor never came: a failed run whether or not --check was given.
            print(f"udp: no frame arrived within --wait {args.wait:g} s")
            status = 1
        if lsl is not None and lsl["ended"] == "wait":
            print(f"lsl: no frame arrived within --wait {args.wait:g} s")
            status = 1
        if args.check:
            word = out["latency_check"]["status"]
            print(
                f"check: {'passed' if status == 0 else 'FAILED'} ({word}"
                + ("" if not replayed or args.paced else f"; {UNPACED_NOTE}")
                + ")"
            )
    return _finish(args, out, status)


def _busy_poll_notes(args: argparse.Namespace, opts: RealtimeOptions) -> list[str]:
    """One-line warnings for ``--busy-poll`` combinations that defeat it."""
    if not args.busy_poll:
        return []
    notes = []
    if opts.priority == "fifo":
        notes.append(
            "--busy-poll with --priority fifo: the kernel's RT throttling "
            "(/proc/sys/kernel/sched_rt_runtime_us) stops a thread that never sleeps "
            "for the rest of each period (50 ms of every 1 s by default); prefer "
            "--spin-us, or --busy-poll at normal priority on an isolated core"
        )
    if opts.cpus is None:
        notes.append("--busy-poll burns one core: give it one with --cpus")
    return notes


def _realtime_options(args: argparse.Namespace) -> RealtimeOptions:
    """The real-time options of the command line (``--realtime`` fills the unset ones)."""
    priority = args.priority
    if args.realtime and priority == "normal":
        priority = "fifo"
    return options_from_text(
        cpus=args.cpus,
        priority=priority,
        freeze_gc=args.freeze_gc or args.realtime,
        pin_threads=args.pin_threads or args.realtime,
        allow_spinning=args.spin,
    )


def _finish(args: argparse.Namespace, out: dict[str, Any], status: int) -> int:
    """--report-modules and --json, then the exit status."""
    if args.report_modules:
        heavy = heavy_modules_loaded()
        out["heavy_modules_loaded"] = heavy
        print("heavy modules loaded: " + (", ".join(heavy) if heavy else "none"))
    if args.json is not None:
        text = json.dumps({"format": SUMMARY_FORMAT, **out}, indent=2) + "\n"
        write_out_file(args.json, text, **_json_out(args))
    return status


def main(argv: Sequence[str] | None = None) -> None:
    """Entry point of the ``slipkit-run`` console script."""
    try:
        status = run(argv)
    except SlipkitError as exc:
        print(f"slipkit-run: error: {' '.join(str(exc).split())}", file=sys.stderr)
        raise SystemExit(2) from None
    raise SystemExit(status)


if __name__ == "__main__":
    main()
