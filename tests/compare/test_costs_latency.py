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
