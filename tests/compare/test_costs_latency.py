"""compare's cost step times a bundle by the runtime's latency rule (as slipkit-run --check)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from tests.runtime.test_prepare import _detector, _manifest, _stream

from slipkit.compare.costs import time_bundle
from slipkit.families.sliptack.export.detector import export_speed_slip_detector
from slipkit.runtime import ReplaySource, StreamLoop, load_bundle, write_bundle
from slipkit.runtime.budget import block_p99


@pytest.fixture(scope="module")
def prepared(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A SlipTack-like bundle with a prepare graph (1 kHz, window 300, hop 10)."""
    g = export_speed_slip_detector(_detector(), prepare=True)
    return write_bundle(
        tmp_path_factory.mktemp("costs") / "prepared",
        g.serialize(),
        _manifest(g.prepare_tensor),
        replay=_stream(),
        prepare=g.serialize_prepare(),
    )


def test_cost_step_times_prepare_frames_paced(prepared: Path) -> None:
    """The cost step pools the prepare frames with the decisions (as --check judges them),
    paces the replay, and reports the rule's p99 of them."""
    frames, times = _stream()
    ref = StreamLoop(load_bundle(prepared)).run(ReplaySource(frames, times))
    cost = time_bundle(prepared, max_frames=len(frames), warmup=2)
    assert (
        len(ref.latency_ns) + len(ref.prepare_latency_ns),
        True,
        block_p99(cost.latency_us),
    ) == (len(cost.latency_us), cost.paced, cost.p99_us)
    assert np.isfinite(cost.p99_us)


@pytest.mark.parametrize("diagnose", [True, False])
def test_back_to_back_replay_only_when_paced_p99_fails(
    prepared: Path, monkeypatch: pytest.MonkeyPatch, diagnose: bool
) -> None:
    """A paced p99 that is not within the budget is replayed once more back to back
    (the same frames, decisions and prepare frames pooled); otherwise not. The budget
    stays the manifest's per-frame one whatever the hop (10 here): the loop makes each
    decision within its frame's step."""
    import slipkit.compare.costs as costs

    monkeypatch.setattr(costs, "needs_unpaced", lambda judged: diagnose)
    frames, times = _stream()
    n = 400
    ref = StreamLoop(load_bundle(prepared)).run(ReplaySource(frames[:n], times[:n]))
    cost = time_bundle(prepared, max_frames=n, warmup=2)
    expect = len(ref.latency_ns) + len(ref.prepare_latency_ns) if diagnose else 0
    assert (len(cost.unpaced_latency_us), cost.hop, cost.budget_p99_us) == (
        expect,
        10,
        pytest.approx(100.0),
    )
    assert (
        cost.p99_unpaced_us == block_p99(cost.unpaced_latency_us)
        if diagnose
        else np.isnan(cost.p99_unpaced_us)
    )


def test_needs_unpaced_follows_the_rule() -> None:
    """Borderline and over call for the back-to-back replay; within and unmeasured not."""
    from slipkit.compare.costs import needs_unpaced
    from slipkit.runtime.budget import judge_p99

    got = [needs_unpaced(judge_p99(p, 100.0)) for p in (50.0, 90.0, 300.0, np.nan)]
    assert got == [False, True, True, False]
