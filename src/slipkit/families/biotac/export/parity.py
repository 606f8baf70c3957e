"""Parity and per-call time of the BioTac force-derivative and pressure-vibration graphs on
simulated lifts: ``python -m slipkit.families.biotac.export.parity`` prints them.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from slipkit.baselines.base import StreamDetector
from slipkit.export.detectors import (
    DetectorGraph,
    _simulate,
    _stack,
    print_parity_rows,
)
from slipkit.families.biotac.detectors import ForceDerivative, PressureVibration
from slipkit.families.biotac.export.detectors import (
    export_force_derivative,
    export_pressure_vibration,
    pressure_baseline,
)


def main() -> None:
    """Print parity and per-call time of the BioTac detector graphs on simulated lifts.

    ``python -m slipkit.families.biotac.export.parity``: thresholds fitted on 3
    ``biotac_lift_slip`` trials (seed 5), parity
    (:func:`~slipkit.export.detector_parity.check_detector_parity`) on 3 other trials
    (seed 6); time = median of 2000 batch-1 onnxruntime calls (one thread) on held-out
    windows.
    """
    rows: list[tuple[str, StreamDetector, DetectorGraph, Any, Any]] = []
    fit_ds, held = (
        _simulate("biotac_lift_slip", 3, 5),
        _simulate("biotac_lift_slip", 3, 6),
    )
    X, y, seg = _stack(fit_ds, "truth_force", ["fx", "fy"], "slip_onset_s")
    Xh, _, sh = _stack(held, "truth_force", ["fx", "fy"], "slip_onset_s")
    for thr in (0.5, None):
        det = ForceDerivative(threshold=thr).fit(X, y, segments=seg)
        rows.append(
            ("ForceDerivative (fx, fy)", det, export_force_derivative(det), Xh, sh)
        )
    X, y, seg = _stack(fit_ds, "pac", ["pac"], "slip_onset_s")
    Xh, _, sh = _stack(held, "pac", ["pac"], "slip_onset_s")
    base = pressure_baseline(PressureVibration(), X, segments=seg)
    for thr in (2.0, None):
        det = PressureVibration(baseline=base, threshold=thr).fit(X, y, segments=seg)
        rows.append(("PressureVibration", det, export_pressure_vibration(det), Xh, sh))
    tail = float(rows[-1][2].features["tail"])  # type: ignore[index]
    swing = max(float(np.ptp(Xh[sh == k])) for k in np.unique(sh))
    print(
        f"pressure baseline (median over the fit trials): {base:.3f} counts; filter tail "
        f"T(L) = {tail:.2e}, largest held-out swing {swing:.0f} counts -> score error "
        f"bound T(L) x swing / baseline = {tail * swing / base:.1e}"
    )
    print_parity_rows(rows)


if __name__ == "__main__":
    main()
