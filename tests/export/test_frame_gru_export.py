"""FrameGRUDetector's step graph: exported, bundled with a state section, run by StreamLoop."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from tests.models.test_frame_gru import recordings

from slipkit.export import ExportError, exporter_for
from slipkit.export.frame_gru import (
    check_step_parity,
    export_frame_gru,
    write_frame_gru_bundle,
)
from slipkit.models.frame_gru import FrameGRUDetector
from slipkit.runtime import StreamLoop, load_bundle

RATE_HZ = 300.0


@pytest.fixture(scope="module")
def fitted() -> FrameGRUDetector:
    X, y, seg = recordings(4)
    return FrameGRUDetector(hidden=8, chunk=32, epochs=8).fit(X, y, segments=seg)


def test_frame_gru_has_its_exporter(fitted: FrameGRUDetector) -> None:
    """The registry gives FrameGRUDetector the step-graph exporter."""
    assert export_frame_gru == exporter_for(fitted)


def test_loop_over_a_recording_equals_batch_scores(
    fitted: FrameGRUDetector, tmp_path: Path
) -> None:
    """The written bundle in StreamLoop scores a held-out recording as decision_function, within 1e-5."""
    X, _, seg = recordings(2, seed=5)
    held = [X[seg == i] for i in range(2)]
    parity = write_frame_gru_bundle(
        fitted,
        tmp_path / "gru",
        held,
        name="gru",
        stream="s",
        channels=["a", "b"],
        rate_hz=RATE_HZ,
    )
    bundle = load_bundle(tmp_path / "gru")
    loop = StreamLoop(bundle)
    for i, row in enumerate(held[0]):
        loop.step(row, i / RATE_HZ)
    result = loop.result()
    want = fitted.decision_function(held[0])
    assert (True, len(want), 1) == (
        parity["ok"],
        len(result.score),
        len(bundle.manifest.state),
    )
    np.testing.assert_allclose(result.score, want, rtol=0, atol=1e-5)
    np.testing.assert_array_equal(result.slip, want >= fitted.threshold_)


def test_failed_parity_leaves_no_bundle(
    fitted: FrameGRUDetector, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """When the loop disagrees with the detector, the export raises and writes nothing."""
    import slipkit.export.frame_gru as mod

    def bad(*args: object, **kwargs: object) -> dict[str, object]:
        return {"ok": False, "max_abs_diff": 1.0, "tol": 1e-5, "decisions_equal": True}

    monkeypatch.setattr(mod, "check_step_parity", bad)
    X, _, _ = recordings(1, seed=6)
    with pytest.raises(ExportError, match="parity failed"):
        write_frame_gru_bundle(
            fitted,
            tmp_path / "gru",
            [X],
            name="g",
            stream="s",
            channels=["a", "b"],
            rate_hz=RATE_HZ,
        )
    assert [] == list(tmp_path.iterdir())


def test_parity_holds_across_a_nan_frame(
    fitted: FrameGRUDetector, tmp_path: Path
) -> None:
    """A held-out recording with a NaN frame: the loop restarts its state as the detector does."""
    X, _, _ = recordings(1, seed=7)
    X[50, 0] = np.nan
    out = write_frame_gru_bundle(
        fitted,
        tmp_path / "gru",
        [X],
        name="g",
        stream="s",
        channels=["a", "b"],
        rate_hz=RATE_HZ,
    )
    again = check_step_parity(tmp_path / "gru", fitted, [X], rate_hz=RATE_HZ)
    assert (True, True, len(X)) == (out["ok"], again["ok"], again["frames"])


def test_stateful_replay_leaves_a_gap_between_trials() -> None:
    """replay(gap_periods=10) starts each trial 10 frame periods after the last; the default joins them."""
    import numpy as np

    from slipkit.export.deploy import Deployment, HeldOutTrial

    trials = [
        HeldOutTrial(f"t{i}", np.zeros((3, 2)), np.arange(3) / 100.0 + 5.0 * i)
        for i in range(2)
    ]
    dep = Deployment(
        frame={"rate_hz": 100.0},
        preprocessing=[],
        export_options={},
        positive=None,
        debounce_k=1,
        trials=trials,
    )
    _, joined = dep.replay()
    _, gapped = dep.replay(gap_periods=10.0)
    assert [0.01, 0.10] == [
        round(float(joined[3] - joined[2]), 9),
        round(float(gapped[3] - gapped[2]), 9),
    ]
