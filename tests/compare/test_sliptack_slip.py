"""The SlipTack slip-detection comparison: onset detectors beside band energy, ranked on
trial events, and the demo's SlipTack grasp taken from its verdict."""

from __future__ import annotations

from pathlib import Path

import pandas as pd
from hydra import compose, initialize_config_dir

from slipkit import config_dir
from slipkit.compare.commands import compare_main


def test_onset_detects_every_slip_earlier_than_band_energy(tmp_path: Path) -> None:
    """On the hard pull: the deflection-rate onset catches every test slip without an
    early alarm, and declares earlier than the band-energy detector; all export."""
    out = tmp_path / "sliptack_slip"
    with initialize_config_dir(config_dir=str(config_dir()), version_base="1.3"):
        cfg = compose(
            config_name="compare",
            overrides=[
                "comparison=sliptack_slip",
                "comparison.dataset.n_trials=6",
                "~comparison.estimators.onset_logistic",
                f"out={out}",
                "progress=false",
                "cost.max_frames=100",
                "cost.warmup=2",
            ],
        )
    compare_main(cfg)
    df = pd.read_csv(out / "metrics.csv").set_index("estimator")
    assert ["onset", "energy"] == df.index.tolist()
    assert ["ok", "ok"] == df["export"].tolist()
    onset, energy = df.loc["onset"], df.loc["energy"]
    assert (1.0, 0.0) == (
        float(onset["detected_rate"]),
        float(onset["early_alarm_rate"]),
    )
    assert float(onset["delay_ms"]) < float(energy["delay_ms"])


def test_the_demo_fills_the_sliptack_grasp_from_the_slip_verdict() -> None:
    """The SlipTack scenario fills the slip-detection row, not the speed row, and every
    estimator of that comparison has its closed-loop detector."""
    with initialize_config_dir(config_dir=str(config_dir()), version_base="1.3"):
        demo = compose(config_name="demo")
        comp = compose(
            config_name="compare", overrides=["comparison=sliptack_slip"]
        ).comparison
        node = compose(config_name="closedloop", overrides=["closedloop=sliptack"])
    assert "sliptack_slip" == demo.closedloop.families.sliptack
    assert {"sliptack", "sliptack_slip"} <= set(demo.comparisons)
    shown = dict(demo.closedloop.detector.sliptack)
    names = set(node.closedloop.detectors)
    for est in comp.estimators:
        assert shown.get(est, est) in names, est


def test_every_demo_comparison_composes_in_both_modes() -> None:
    """The demo's per-family overrides compose with and without quick=true (a quick
    override repeating a deletion of the full one fails here, not in `make demo`)."""
    from slipkit.demo import _plan

    for quick in (False, True):
        with initialize_config_dir(config_dir=str(config_dir()), version_base="1.3"):
            cfg = compose(config_name="demo", overrides=[f"quick={str(quick).lower()}"])
            plan = _plan(cfg, present={})
        want = set(cfg.comparisons) - set(cfg.real_comparisons)
        if quick:
            want -= set(cfg.quick_skip)
        assert want == set(plan), quick
        speed = plan["sliptack"].comparison
        assert not {"onset", "onset_logistic"} & set(speed.estimators), quick
