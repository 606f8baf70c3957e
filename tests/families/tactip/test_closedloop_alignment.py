"""slipkit closedloop scenario=tactip: the analytic pin-motion bundles (alignment_k1, alignment_fast_k1) in the loop."""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path

import pandas as pd
import pytest
from hydra import compose, initialize_config_dir
from hydra.core.global_hydra import GlobalHydra

from slipkit import config_dir
from slipkit.closedloop.commands import closedloop_main
from slipkit.closedloop.detectors import Detector
from slipkit.closedloop.plant import PlantState
from slipkit.errors import SlipkitError
from slipkit.families.tactip.scenario import check_frame, pin_channels


def _run(overrides: list[str]) -> None:
    with initialize_config_dir(config_dir=str(config_dir()), version_base="1.3"):
        closedloop_main(compose(config_name="closedloop", overrides=overrides))


@pytest.fixture(scope="module")
def alignment_run(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Path]:
    """alignment_k1 alone on 3 speeds, 1 seed, 2 trials per speed, 8 training trials."""
    out = tmp_path_factory.mktemp("closedloop_alignment") / "cl"
    drop = [
        f"~closedloop.detectors.{d}"
        for d in (
            "svm_k1",
            "svm_k2",
            "svm_k3",
            "svm_k4",
            "svm_linear_k2",
            "svm_tuned_k2",
        )
    ]
    _run(
        [
            f"out={out}",
            "seeds=[0]",
            "trials_per_speed=2",
            "train_trials=8",
            "closedloop.speeds.n=3",
            "closedloop.speeds.hi=2.0",
            "closedloop.oracle_delays_ms=[]",
            *drop,
        ]
    )
    yield out
    GlobalHydra.instance().clear()


def test_alignment_bundle_catches_slips(alignment_run: Path) -> None:
    """The exported pin-motion bundle declares every slip at or after its onset and no object is dropped."""
    results = pd.read_csv(alignment_run / "results.csv")
    rows = results[results.detector == "alignment_k1"]
    assert (6, 6, 0, 0) == (
        len(rows),
        int((rows.delay_ms >= 0).sum()),
        int(rows.false_alarm.sum()),
        int(rows.dropped.sum()),
    )


def test_alignment_bundle_reads_the_raw_pins_stream(alignment_run: Path) -> None:
    """The bundle's frame is the sensor's: stream pins, x0..x126 then y0..y126, 120 Hz, debounce 1."""
    manifest = json.loads(
        (alignment_run / "bundles" / "alignment_k1" / "manifest.json").read_text()
    )
    frame = manifest["frame"]
    assert (["pins"], list(pin_channels(127)), 120.0, 1) == (
        frame["streams"],
        frame["channels"],
        float(frame["rate_hz"]),
        int(manifest["debounce"]["k"]),
    )


@pytest.fixture(scope="module")
def fast_run(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Path]:
    """Both pin-motion detectors at the fast retractions (11.8 and 20 mm/s), 1 seed, 2 trials each."""
    out = tmp_path_factory.mktemp("closedloop_alignment_fast") / "cl"
    drop = [
        f"~closedloop.detectors.{d}"
        for d in ("svm_k1", "svm_k2", "svm_k3", "svm_k4", "svm_linear_k2")
    ]
    _run(
        [
            f"out={out}",
            "seeds=[0]",
            "trials_per_speed=2",
            "train_trials=8",
            "closedloop.speeds.lo=11.8",
            "closedloop.speeds.hi=20.0",
            "closedloop.speeds.n=2",
            "closedloop.oracle_delays_ms=[]",
            *drop,
        ]
    )
    yield out
    GlobalHydra.instance().clear()


def test_fast_alignment_catches_the_fast_slips_the_slow_one_drops(
    fast_run: Path,
) -> None:
    """At 11.8-20 mm/s most slips start before alignment_k1's 24-frame window (0.19 s) is full,
    so it drops those objects (all at 20 mm/s); alignment_fast_k1 (6 frames) declares every slip
    at or after its onset, with no false alarm and no drop."""
    results = pd.read_csv(fast_run / "results.csv")
    fast = results[results.detector == "alignment_fast_k1"]
    slow = results[results.detector == "alignment_k1"]
    assert ((4, 4, 0, 0), (2, 2)) == (
        (
            len(fast),
            int((fast.delay_ms >= 0).sum()),
            int(fast.false_alarm.sum()),
            int(fast.dropped.sum()),
        ),
        (
            int((slow.condition == 20.0).sum()),
            int(slow[slow.condition == 20.0].dropped.sum()),
        ),
    )
    assert int(slow.dropped.sum()) >= 3  # and one of the two at 11.8 mm/s


def test_fast_alignment_bundle_is_a_6_frame_window(fast_run: Path) -> None:
    """The fast config exports a window of 6 frames (lookback 4 + gap 1 + 1) on the raw pins, debounce 1."""
    manifest = json.loads(
        (fast_run / "bundles" / "alignment_fast_k1" / "manifest.json").read_text()
    )
    assert ([1, 6, 254], 1, ["pins"]) == (
        manifest["inputs"][0]["shape"],
        int(manifest["debounce"]["k"]),
        manifest["frame"]["streams"],
    )


class _Reads(Detector):
    """A detector reading the given channels at the given rate (never declares)."""

    def __init__(self, channels: tuple[str, ...], rate_hz: float) -> None:
        self.name = "wrong"
        self.channels = channels
        self.rate_hz = rate_hz

    def decide(self, state: PlantState, frame: object) -> bool:
        """Never."""
        del state, frame
        return False


class _Sensor:
    """What check_frame reads of a TacTipSensor: the rest layout and the camera rate."""

    class _Trial:
        rest_xy = [(0.0, 0.0)] * 127

    class _Model:
        rate_hz = 120.0

    trial = _Trial()
    model = _Model()


@pytest.mark.parametrize(
    ("channels", "rate", "match"),
    [
        (pin_channels(331), 120.0, "reads 662 channels.*makes 254"),
        (
            pin_channels(127)[127:] + pin_channels(127)[:127],
            120.0,
            "first differ at position 0",
        ),
        (pin_channels(127), 60.0, "60 Hz"),
    ],
)
def test_a_bundle_of_another_frame_is_refused(
    channels: tuple[str, ...], rate: float, match: str
) -> None:
    """Another pin count, channel order or frame rate is a SlipkitError naming the detector."""
    with pytest.raises(SlipkitError, match=f"closedloop.detectors.wrong: .*{match}"):
        check_frame(_Reads(channels, rate), _Sensor(), "tactip_gravity_drop")  # type: ignore[arg-type]
