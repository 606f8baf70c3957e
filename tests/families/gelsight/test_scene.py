"""The simulated GelSight grasp: slips spread the marker field, wiggles move it and
return, blur and dim light cost markers, and the output reads like an import."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("cv2")

import slipkit.families.gelsight.effects  # noqa: F401  (registers the effects)
from slipkit.families.gelsight.features import (
    affine_fit,
    pitch_of,
    to_points,
    trial_features,
)
from slipkit.families.gelsight.report import load_trials
from slipkit.families.gelsight.scene import GelSightGrasp
from slipkit.sim.core import Scene, SimulationError


def model(**kw: object) -> GelSightGrasp:
    base: dict[str, object] = {
        "duration_s": 3.0,
        "onset_s": [0.5, 1.0],
        "slide_s": [0.5, 0.8],
        "set_down_s": 2.0,
        "objects": 5,
    }
    base.update(kw)
    return GelSightGrasp(**base)  # type: ignore[arg-type]


def first_of(scene: Scene, slipped: bool, seed: int = 0) -> object:
    for i in range(60):
        tr = scene.run_trial(i, seed)
        if bool(tr.labels["slipped"]) == slipped:
            return tr
    raise AssertionError("no trial of that label in 60")


def pins(tr: object, cam: str = "camera_0") -> np.ndarray:
    df = tr.streams[cam]  # type: ignore[attr-defined]
    return df.drop(columns=["t"]).to_numpy(np.float64)


def max_divergence(frames: np.ndarray) -> float:
    f = trial_features(frames, window=50, arm=3)
    return float(np.nanmax(np.abs(f[:, 1])))


def net_divergence(frames: np.ndarray) -> float:
    p = to_points(frames)
    pitch = pitch_of(p[0])
    a, _, _ = affine_fit(p[0] / pitch, (p[-1] - p[0]) / pitch)
    return float(a[0, 0] + a[1, 1])


def test_a_slip_spreads_the_field_a_wiggle_moves_it_and_returns() -> None:
    slip = first_of(Scene("s", model(), {"gel_shear": {"follow": 1.0}}), True)
    wiggle = first_of(
        Scene(
            "w",
            model(),
            {"shake": {"count": 3, "amplitude": 0.15}, "gel_shear": {}},
        ),
        False,
    )
    s, w = pins(slip), pins(wiggle)
    assert max_divergence(s) > 2 * max_divergence(w)
    # net: the slip's gel contracts back from the load's spreading; the wiggle's does not
    assert net_divergence(s) < -0.01
    assert abs(net_divergence(w)) < 1e-3
    pw = to_points(w)
    moved = np.nanmax(np.linalg.norm(np.nanmean(pw - pw[0], axis=1), axis=1))
    net = np.linalg.norm(np.nanmean(pw[-1] - pw[0], axis=0))
    assert moved > 0.5  # px: the shake moves the field ...
    assert net < 0.1 * moved  # ... and the field returns
    ps = to_points(s)
    assert np.allclose(ps[-1], ps[-5])  # the object has left: the markers are still


def test_same_seed_same_trial_and_equal_lengths() -> None:
    scene = Scene(
        "g", model(duration_s=2.0, onset_s=0.5, set_down_s=1.0), {"shake": {}}
    )
    a, b = scene.run_trial(3, 7), scene.run_trial(3, 7)
    assert a.streams["camera_0"].equals(b.streams["camera_0"])
    assert not a.streams["camera_0"].equals(scene.run_trial(3, 8).streams["camera_0"])
    lengths = {len(scene.run_trial(i, 0).streams["camera_2"]) for i in range(12)}
    assert lengths == {50}


def test_blur_and_dim_light_cost_markers() -> None:
    m = model(duration_s=1.0, onset_s=0.2, set_down_s=0.5, objects=2)
    found = {}
    for key, fx in {
        "sharp": {},
        "blur": {"blur": {"sigma_px": 4.0}},
        "dim": {"lighting_drift": {"gain": -0.85, "gradient": 0.0}},
    }.items():
        scene = Scene(key, m, {"gel_shear": {}, "marker_grid": {}, **fx})
        found[key] = scene.run_trial(0, 0).meta["camera_0.markers_found_mean"]
    assert found["blur"] < found["sharp"] - 2
    assert found["dim"] < found["sharp"] - 2


def test_the_dataset_reads_like_an_import() -> None:
    ds = Scene("g", model(duration_s=1.0, onset_s=0.2, set_down_s=0.5), {}).simulate(
        6, 0
    )
    trials, y, groups, _ = load_trials(ds)
    assert set(ds.streams) == {"camera_0", "camera_2", "fingertips"}
    assert set(trials[0]) == {"camera_0", "camera_2"}
    assert trials[0]["camera_0"].shape == (25, 60)
    # the side-by-side stream: camera_0's block, then camera_2's
    both = ds[ds.trial_ids[0]].streams["fingertips"]
    assert ["camera_0_x_0", "camera_2_y_29"] == [both.columns[1], both.columns[-1]]
    np.testing.assert_array_equal(both.iloc[:, 1:61].to_numpy(), trials[0]["camera_0"])
    np.testing.assert_array_equal(both.iloc[:, 61:].to_numpy(), trials[0]["camera_2"])
    assert set(y) <= {0, 1}
    assert all(g.startswith("object_") for g in groups)


def test_bad_config_names_the_key() -> None:
    with pytest.raises(SimulationError, match=r"model\.onset_s"):
        GelSightGrasp(duration_s=2.0, onset_s=[0.5, 3.0])
    with pytest.raises(SimulationError, match="before 'gel_shear'"):
        Scene("g", model(), {"gel_shear": {}, "shake": {}}).run_trial(0, 0)
    with pytest.raises(SimulationError, match="after 'marker_grid'"):
        Scene("g", model(), {"blur": {"sigma_px": 1.0}}).run_trial(0, 0)
