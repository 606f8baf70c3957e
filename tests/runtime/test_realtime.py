"""Real-time options: parsing, affinity / priority without tracebacks, frozen GC, pinned threads, no per-frame allocation."""

from __future__ import annotations

import gc
import json
import os
import subprocess
import sys
import tracemalloc
from pathlib import Path

import numpy as np
import pytest
from tests.runtime.helpers import LinearCase

from slipkit.runtime import StreamLoop, load_bundle
from slipkit.runtime.cli import run
from slipkit.runtime.errors import OptionError
from slipkit.runtime.realtime import (
    RealtimeOptions,
    apply_realtime,
    blas_threads,
    frozen_gc,
    options_from_text,
    parse_cpus,
    parse_priority,
    pinned_session,
)
from slipkit.runtime.session import SessionSpec


def test_parse_cpus_reads_lists_and_ranges() -> None:
    """'0,2-3' reads as cores 0, 2 and 3 (sorted, duplicates merged)."""
    assert (0, 2, 3) == parse_cpus("3,0,2-3")


@pytest.mark.parametrize("text", ["", "a", "3-1", "-1", "1,,2"])
def test_parse_cpus_refuses_bad_text_naming_the_option(text: str) -> None:
    """A core list that is not numbers and ranges is an OptionError naming --cpus."""
    with pytest.raises(OptionError, match="--cpus"):
        parse_cpus(text)


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("normal", ("normal", None)),
        ("fifo", ("fifo", None)),
        ("fifo:20", ("fifo", 20)),
        ("nice:-5", ("nice", -5)),
    ],
)
def test_parse_priority(text: str, expected: tuple[str, int | None]) -> None:
    """Priority texts read as (kind, value)."""
    assert expected == parse_priority(text)


@pytest.mark.parametrize("text", ["rt", "fifo:x", "normal:3", "fifo:0", "nice:-30"])
def test_bad_priority_is_an_option_error(text: str) -> None:
    """A priority that is unknown, not a number or out of range names --priority."""
    with pytest.raises(OptionError, match="--priority"):
        options_from_text(priority=text)


def test_fifo_not_permitted_is_one_note_not_an_exception(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Without permission SCHED_FIFO is skipped with one line naming the option and the fix."""

    def refuse(*args: object) -> None:
        raise PermissionError(1, "Operation not permitted")

    monkeypatch.setattr(os, "sched_setscheduler", refuse)
    state = apply_realtime(RealtimeOptions(priority="fifo"))
    assert {} == state.applied
    assert 1 == len(state.notes)
    assert state.notes[0].startswith("--priority fifo:10 not permitted")
    assert "\n" not in state.notes[0]


def test_nice_and_affinity_apply_to_a_process() -> None:
    """A positive nice increment and a one-core affinity take effect on a child process."""
    child = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(30)"])
    try:
        core = min(os.sched_getaffinity(0))
        before = os.getpriority(os.PRIO_PROCESS, child.pid)
        state = apply_realtime(
            RealtimeOptions(cpus=(core,), priority="nice", nice=3), pid=child.pid
        )
        assert [] == state.notes
        assert {core} == os.sched_getaffinity(child.pid)
        assert before + 3 == os.getpriority(os.PRIO_PROCESS, child.pid)
        assert f"nice:{before + 3}" == state.applied["priority"]
    finally:
        child.kill()
        child.wait()


def test_missing_core_is_a_note() -> None:
    """Pinning to a core that does not exist is skipped with a note listing the cores."""
    state = apply_realtime(RealtimeOptions(cpus=(4095,)))
    assert 1 == len(state.notes)
    assert state.notes[0].startswith("--cpus 4095: not applied")


def test_frozen_gc_disables_and_restores() -> None:
    """Inside frozen_gc the collector is off with objects frozen; after, both are restored."""
    assert gc.isenabled()
    with frozen_gc():
        inside = (gc.isenabled(), gc.get_freeze_count() > 0)
    assert (False, True) == inside
    assert (True, 0) == (gc.isenabled(), gc.get_freeze_count())


def test_pinned_session_sets_one_thread_each() -> None:
    """pin_threads gives one intra-op and one inter-op thread and the spinning choice."""
    spec = SessionSpec(intra_op_num_threads=2, inter_op_num_threads=2, warmup=7)
    out = pinned_session(spec, RealtimeOptions(pin_threads=True, allow_spinning=True))
    assert (1, 1, True, 7) == (
        out.intra_op_num_threads,
        out.inter_op_num_threads,
        out.allow_spinning,
        out.warmup,
    )
    assert spec == pinned_session(spec, RealtimeOptions())


class _NoOpSession:
    """Stands in for onnxruntime (whose pybind call allocates its own bookkeeping)."""

    def run_with_iobinding(self, binding: object) -> None:
        return None


def _steady_memory(loop: StreamLoop, frames: list[np.ndarray]) -> tuple[int, int]:
    """(memory kept, peak above the start) in bytes over 1000 warm steps, GC frozen."""
    for i in range(200):
        loop.step(frames[i], i / 100.0)
    with frozen_gc():
        tracemalloc.start()
        try:
            start = tracemalloc.get_traced_memory()[0]
            tracemalloc.reset_peak()
            for i in range(200, 1200):
                loop.step(frames[i], i / 100.0)
            current, peak = tracemalloc.get_traced_memory()
        finally:
            tracemalloc.stop()
    return current - start, peak - start


def test_steady_state_steps_allocate_no_arrays(tmp_path: Path) -> None:
    """Once warm, 1000 steps of the loop's own code (a 64-frame window) never hold a window-sized temporary."""
    case = LinearCase(tmp_path, window=64)
    loop = StreamLoop(load_bundle(case.path), capacity=1 << 12)
    loop._session = _NoOpSession()  # type: ignore[assignment]
    frames = [np.array(f, dtype=np.float64) for f in case.frames] * 6
    kept, peak = _steady_memory(loop, frames)
    # a window of 64 x 3 float64 values is 1.5 KiB: a temporary of that size per
    # step would show in the peak
    window_bytes = 64 * 3 * 8
    assert (True, True) == (kept < 1024, peak < window_bytes)


def test_steady_state_steps_keep_no_memory_with_onnxruntime(tmp_path: Path) -> None:
    """With the real session and the GC frozen, 1000 warm steps keep under 8 KiB (no per-frame leak)."""
    case = LinearCase(tmp_path, window=64)
    loop = StreamLoop(load_bundle(case.path), capacity=1 << 12)
    frames = [np.array(f, dtype=np.float64) for f in case.frames] * 6
    kept, _ = _steady_memory(loop, frames)
    # onnxruntime's own bookkeeping keeps 2.0-4.6 KiB, varying from run to run (the
    # loop before the hop-1 fast path too); one Python object (>= 16 B) kept per
    # frame would be >= 16 KB.
    assert kept < 8192


def test_cli_realtime_options_run_and_report(
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    """slipkit-run --realtime without permission runs, notes one line, and reports the options in --json."""

    def refuse(*args: object) -> None:
        raise PermissionError(1, "Operation not permitted")

    monkeypatch.setattr(os, "sched_setscheduler", refuse)
    case = LinearCase(tmp_path)
    out = tmp_path / "out.json"
    status = run([str(case.path), "--realtime", "--json", str(out)])
    err = capsys.readouterr().err.strip().splitlines()
    summary = json.loads(out.read_text())
    assert 0 == status
    assert 1 == len(err)
    assert err[0].startswith("slipkit-run: note: --priority fifo:10 not permitted")
    assert (True, True, "fifo") == (
        summary["realtime"]["freeze_gc"],
        summary["realtime"]["pin_threads"],
        summary["realtime"]["priority"],
    )
    assert (1, 1) == (
        summary["session"]["intra_op_num_threads"],
        summary["session"]["inter_op_num_threads"],
    )


def test_cli_bad_cpus_is_one_line_exit_2(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A bad --cpus is one error line naming the option, exit status 2."""
    from slipkit.runtime.cli import main

    case = LinearCase(tmp_path)
    with pytest.raises(SystemExit) as exc:
        main([str(case.path), "--cpus", "x"])
    err = capsys.readouterr().err.strip().splitlines()
    assert 2 == exc.value.code
    assert 1 == len(err)
    assert err[0].startswith("slipkit-run: error: --cpus")


def test_blas_threads_sets_and_reports_openblas_threads() -> None:
    """blas_threads(1) leaves numpy's OpenBLAS on one thread (and reports it); the old count is restored after."""
    before = blas_threads()
    if before is None:
        pytest.skip("numpy is not linked to OpenBLAS here")
    try:
        assert (1, 1) == (blas_threads(1), blas_threads())
    finally:
        blas_threads(before)
