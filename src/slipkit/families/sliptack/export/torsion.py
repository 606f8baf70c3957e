"""Exporter of the SlipTack torsional-slip detector (band-pass, then the RMS of the last
window).

The graph contract: :mod:`slipkit.export.detectors`.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from sklearn.utils.validation import check_is_fitted

from slipkit.export._graph import GraphBuilder
from slipkit.export.detector_graph import (
    DEFAULT_TAIL_TOL,
    DetectorGraph,
    _axes,
    _band_matrix,
    _finish,
    _graph,
    _prologue,
    steady_state_fir,
)
from slipkit.export.registry import DEFAULT_OPSET, register_exporter
from slipkit.families.sliptack.torsion import TorsionalSlipDetector


# -- SlipTack torsional slip ---------------------------------------------------------------
def export_torsional_slip(
    detector: TorsionalSlipDetector,
    *,
    tail_tol: float = DEFAULT_TAIL_TOL,
    opset: int = DEFAULT_OPSET,
) -> DetectorGraph:
    """Export a fitted :class:`TorsionalSlipDetector`: windowed band-pass, then the RMS.

    Parameters
    ----------
    detector : TorsionalSlipDetector
        Fitted.
    tail_tol : float
        Tail of the band-pass impulse response left out (:func:`steady_state_fir`);
        1e-5 gives ``W = 991`` samples for 5-15 Hz at 1 kHz with the RMS over 100.
    opset : int
        Default-domain opset (17 or 18).

    Returns
    -------
    DetectorGraph
        Input ``(batch, W, 1)`` nib signal (e.g. mm), oldest first, NaN read as 0;
        ``score`` ``(batch,)``: RMS of the band over the last ``window`` outputs.
        The batch detector starts its filter at rest (zero state), the graph in the
        steady state of the window's first sample; they agree once the batch
        filter's start transient has decayed, which the tail bound covers from
        sample ``W - 1`` (``first_decision``) on.
    """
    check_is_fitted(detector, "threshold_")
    sos = detector._sos()
    n_out = int(detector.window)
    m, tail = steady_state_fir(sos, n_out, tail_tol=tail_tol)
    w = m.shape[0]
    g = GraphBuilder("torsional_slip", opset)
    inp, x = _prologue(g, w, 1)
    v = g.op("Reshape", x, g.const([-1, w], np.int64), stem="v")
    v = g.op("Where", g.op("IsNaN", v), g.const(0.0, np.float64), v, stem="v_nan0")
    band = _band_matrix(g, v, m)
    ms = g.op(
        "Div",
        g.op("ReduceSum", g.op("Mul", band, band), _axes(g, 1), keepdims=0),
        g.const(float(n_out), np.float64),
        stem="mean_square",
    )
    score64 = g.op("Sqrt", ms, stem="rms")
    lo, hi = (float(f) for f in detector.band_hz)
    model = _finish(
        g,
        inp,
        score64,
        f"TorsionalSlipDetector: RMS over {n_out} samples of the {lo:g}-{hi:g} Hz band "
        f"({w}x{n_out} matrix)",
    )
    import scipy

    return _graph(
        detector,
        model,
        opset=g.opset,
        window=w,
        channels=1,
        hop=1,
        first_decision=w - 1,
        score_meaning=(
            f"TorsionalSlipDetector.decision_function at the window's last sample: RMS "
            f"of the {lo:g}-{hi:g} Hz band over the last {n_out} samples (input unit); "
            "slip ('1') where score >= threshold"
        ),
        input_meaning=f"the last {w} nib samples at {detector.rate_hz:g} Hz, oldest first (NaN: 0)",
        features={
            "band_hz": [lo, hi],
            "order": int(detector.order),
            "filter_window": w,
            "tail_tol": float(tail_tol),
            "tail": tail,
            "n_out": n_out,
        },
        scipy=scipy.__version__,
    )


def _torsion(seed: int) -> tuple[NDArray[np.float64], NDArray[np.int_]]:
    # the recipe of tests/export/test_detector_export.py: drift + noise, a 10 Hz burst
    rng = np.random.default_rng(seed)
    t = np.arange(4000) / 1000.0
    x = 2.0 + 0.3 * t + rng.normal(0, 0.02, len(t))
    on = (t >= 2.0) & (t < 3.0)
    x[on] += 0.2 * np.sin(2 * np.pi * 10 * t[on])
    return x[:, None], on.astype(int)


def main() -> None:
    """Print the torsional graph's parity and per-call time as ``python -m
    slipkit.export.detectors`` does (fit on one synthetic recording, parity on another)."""
    from slipkit.export.detectors import print_parity_rows

    Xt, yt = _torsion(0)
    det = TorsionalSlipDetector().fit(Xt, yt)
    print_parity_rows(
        [
            (
                "TorsionalSlipDetector",
                det,
                export_torsional_slip(det),
                _torsion(1)[0],
                None,
            )
        ]
    )


# ``python -m`` runs a second copy of this module as __main__; only the imported one registers
if __name__ == "__main__":
    main()
else:
    register_exporter(TorsionalSlipDetector, export_torsional_slip)
