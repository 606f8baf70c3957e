"""Parity and per-call time of the FSR touch-and-slip graphs on simulated recordings:
``python -m slipkit.families.fsr.export.parity`` prints them.
"""

from __future__ import annotations

import warnings
from typing import Any

from slipkit.baselines.base import StreamDetector
from slipkit.export.detectors import (
    DetectorGraph,
    _simulate,
    _stack,
    print_parity_rows,
)
from slipkit.families.fsr.export.touch_slip import export_fsr_touch_slip
from slipkit.families.fsr.touch_slip import FSRTouchSlip, PolarityWarning


def main() -> None:
    """Print parity and per-call time of the FSR graphs on simulated recordings.

    ``python -m slipkit.families.fsr.export.parity``: thresholds fitted on 3
    ``fsr_probe_slide`` trials (seed 3), parity
    (:func:`~slipkit.export.detector_parity.check_detector_parity`) on 3 other trials
    (seed 4), for voltage and force input and the confirmed variant; then the mixed
    wirings of ``fsr_probe_slide_hard`` (4 trials each, polarity per recording); time =
    median of 2000 batch-1 onnxruntime calls (one thread) on held-out windows.
    """
    rows: list[tuple[str, StreamDetector, DetectorGraph, Any, Any]] = []
    for input_ in ("voltage", "force"):
        X, y, seg = _stack(
            _simulate("fsr_probe_slide", 3, 3), "fsr", ["voltage"], "slip_event"
        )
        Xh, _, sh = _stack(
            _simulate("fsr_probe_slide", 3, 4), "fsr", ["voltage"], "slip_event"
        )
        det: StreamDetector = FSRTouchSlip(input=input_).fit(X, y, segments=seg)
        rows.append(
            (f"FSRTouchSlip ({input_})", det, export_fsr_touch_slip(det), Xh, sh)
        )
    # the confirmed variant (configs/detector/fsr_robust.yaml: 3 peaks within 0.4 s), at
    # the paper's alpha and at the per-sample ROC's (near the noise: many close peaks)
    for thr in (8.0, None):
        det = FSRTouchSlip(confirm_events=3, confirm_window_s=0.4, threshold=thr)
        det.fit(X, y, segments=seg)
        rows.append(
            ("FSRTouchSlip (confirmed)", det, export_fsr_touch_slip(det), Xh, sh)
        )
    # mixed wirings (the hard scene): polarity per recording, the press_sign op before the
    # graph (parity runs it over every call of each held-out recording, as the loop does)
    X, y, seg = _stack(
        _simulate("fsr_probe_slide_hard", 4, 3), "fsr", ["voltage"], "slip_event"
    )
    Xh, _, sh = _stack(
        _simulate("fsr_probe_slide_hard", 4, 4), "fsr", ["voltage"], "slip_event"
    )
    for name, kw in (
        ("FSR per-recording", {}),
        ("FSR per-rec. confirmed", {"confirm_events": 3, "confirm_window_s": 0.4}),
    ):
        det = FSRTouchSlip(threshold=8.0, **kw)  # type: ignore[arg-type]
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", PolarityWarning)
            det.fit(X, y, segments=seg)
        rows.append((name, det, export_fsr_touch_slip(det), Xh, sh))
    print_parity_rows(rows)


if __name__ == "__main__":
    main()
