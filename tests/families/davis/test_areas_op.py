"""The runtime's DAVIS op (``davis_areas``): hand-written labelling and filtering against scipy."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import ndimage

from slipkit.families.davis.polarity import EIGHT, clean_frame
from slipkit.runtime.errors import BundleError
from slipkit.runtime.ops.davis import clean_event_frame, label_components
from slipkit.runtime.preprocessing import Pipeline


@pytest.mark.parametrize("density", [0.05, 0.3, 0.5, 0.7])
def test_labels_equal_scipy_label(density: float) -> None:
    """Labels and count equal scipy.ndimage.label (8-connected) on random frames."""
    rng = np.random.default_rng([16, int(density * 100)])
    for _ in range(40):
        h, w = rng.integers(1, 40, size=2)
        img = rng.random((h, w)) < density
        expected, n_expected = ndimage.label(img, structure=EIGHT)
        actual, n_actual = label_components(img)
        assert (n_expected, expected.tolist()) == (n_actual, actual.tolist())


def test_labels_of_spiral_equal_scipy() -> None:
    """A long winding region (many propagation steps) is one label, as scipy says."""
    img = np.zeros((31, 31), dtype=bool)
    img[::4, :] = True
    img[1::4, -1] = True
    img[2::4, -1] = True
    img[3::4, 0] = True
    expected, n_expected = ndimage.label(img, structure=EIGHT)
    actual, n_actual = label_components(img)
    assert (n_expected, expected.tolist()) == (n_actual, actual.tolist())


@pytest.mark.parametrize("shape", ["square", "lines"])
@pytest.mark.parametrize(
    ("opening", "closing", "area"), [(2, 3, 8), (3, 2, 4), (0, 0, 5)]
)
def test_clean_equals_detector(
    shape: str, opening: int, closing: int, area: int
) -> None:
    """The numpy opening/closing/area filter keeps the pixels the detector keeps."""
    rng = np.random.default_rng([16, opening, closing, area])
    params = {"opening_px": opening, "closing_px": closing, "min_area_px": area}
    for _ in range(30):
        img = rng.random((36, 38)) < rng.uniform(0.05, 0.6)
        expected = clean_frame(img, opening_shape=shape, **params)
        actual = clean_event_frame(img, opening_shape=shape, **params)
        assert expected.tolist() == actual.tolist()


def test_davis_areas_op_gives_detector_areas() -> None:
    """The registered op turns a (pos, neg) count frame into the detector's two areas."""
    rng = np.random.default_rng(7)
    step = {
        "op": "davis_areas",
        "opening_px": 2,
        "opening_shape": "lines",
        "closing_px": 3,
        "min_area_px": 8,
    }
    pipe = Pipeline([step], (1, 2, 30, 32), "manifest.json")
    counts = rng.poisson(0.4, size=(1, 2, 30, 32)).astype(float)
    kw = {k: v for k, v in step.items() if k != "op"}
    expected = [float(clean_frame(counts[0, i] > 0, **kw).sum()) for i in (0, 1)]
    assert expected == pipe(counts)[0].tolist()


@pytest.mark.parametrize(
    ("change", "field"),
    [
        ({"opening_px": 33}, "opening_px"),
        ({"closing_px": -1}, "closing_px"),
        ({"min_area_px": 10_000}, "min_area_px"),
        ({"opening_shape": "disk"}, "opening_shape"),
        ({"radius": 1}, "radius"),
    ],
)
def test_davis_areas_refuses_bad_parameters(change: dict, field: str) -> None:
    """Out-of-range or unknown parameters are refused at load, naming the field."""
    step = {"op": "davis_areas", "opening_px": 2, "closing_px": 3, "min_area_px": 8}
    with pytest.raises(BundleError, match=field):
        Pipeline([{**step, **change}], (1, 2, 20, 20), "manifest.json")


def test_davis_areas_refuses_wrong_frame_shape() -> None:
    """A frame that is not (1, 2, H, W) is refused at load."""
    step = {"op": "davis_areas", "opening_px": 2, "closing_px": 3, "min_area_px": 8}
    with pytest.raises(BundleError, match="preprocessing"):
        Pipeline([step], (2, 2, 20, 20), "manifest.json")
