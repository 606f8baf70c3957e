"""``slipkit export`` writes a model card (``MODEL_CARD.md``) into every bundle, checked like the graph."""

from __future__ import annotations

import json
from pathlib import Path
from types import SimpleNamespace

import onnxruntime
import pytest
from hydra import compose, initialize_config_dir
from omegaconf import DictConfig, OmegaConf
from tests.strategies import make_dataset

from slipkit import config_dir
from slipkit.data.importers import biotacsp_dos, bts3v2
from slipkit.export.card import NOT_RECORDED, cpu_model, data_source, model_card
from slipkit.export.commands import export_main
from slipkit.runtime import BundleError, load_bundle
from slipkit.runtime.bundle import CARD_FILE
from slipkit.train.commands import train_main
from slipkit.train.runs import read_run

#: one analytic detector and one learned model, the cheapest runs of each
RUNS = {
    "fsr": ["experiment=fsr_roc", "dataset.n_trials=4"],
    "tactip_svm": ["experiment=tactip_svm", "dataset.n_trials=4"],
}


def _compose(name: str, overrides: list[str]) -> DictConfig:
    with initialize_config_dir(config_dir=str(config_dir()), version_base="1.3"):
        return compose(config_name=name, overrides=overrides)


@pytest.fixture(scope="module")
def bundles(tmp_path_factory: pytest.TempPathFactory) -> dict[str, tuple[Path, Path]]:
    """(run, bundle) per family; the FSR bundle with the session timing, TacTip without."""
    root = tmp_path_factory.mktemp("card")
    out = {}
    for name, overrides in RUNS.items():
        run = root / f"run_{name}"
        train_main(_compose("train", [*overrides, f"run_dir={run}"]))
        timing = (
            ["session.rounds=1", "session.max_frames=50"]
            if name == "fsr"
            else ["choose_session=false"]
        )
        bundle = root / f"bundle_{name}"
        export_main(_compose("export", [f"run={run}", f"out={bundle}", *timing]))
        out[name] = (run, bundle)
    return out


def _card(bundle: Path) -> str:
    return (bundle / CARD_FILE).read_text(encoding="utf-8")


@pytest.mark.parametrize("name", sorted(RUNS))
def test_card_is_in_the_bundle_and_its_checksums(
    name: str, bundles: dict[str, tuple[Path, Path]]
) -> None:
    _, bundle = bundles[name]
    files = json.loads((bundle / "manifest.json").read_text())["files"]
    assert CARD_FILE in files
    assert _card(bundle) == load_bundle(bundle).card()


@pytest.mark.parametrize(
    ("name", "estimator", "kind"),
    [("fsr", "FSRTouchSlip", "analytic"), ("tactip_svm", "TacTipSVM", "learned")],
)
def test_card_names_the_model_and_its_training_data(
    name: str, estimator: str, kind: str, bundles: dict[str, tuple[Path, Path]]
) -> None:
    run_dir, bundle = bundles[name]
    card, info = _card(bundle), read_run(run_dir).info
    assert f"`{estimator}`" in card
    assert f", {kind}" in card
    scene = info["dataset"]["scene"]
    assert f"simulated scene `{scene}`, seed 0" in card
    assert info["dataset"]["fingerprint"] in card
    assert "- Licence: simulated by slipkit (no external recording)" in card
    assert "simulated scenes only; not checked on real recordings" in card
    assert "2 training / 2 test trials" in card


@pytest.mark.parametrize("name", sorted(RUNS))
def test_card_gives_held_out_metrics_and_the_operating_point(
    name: str, bundles: dict[str, tuple[Path, Path]]
) -> None:
    run_dir, bundle = bundles[name]
    card, metrics = _card(bundle), read_run(run_dir).metrics
    manifest = json.loads((bundle / "manifest.json").read_text())
    held_out = card.split("## Held-out metrics")[1].split("## Operating point")[0]
    for test_id in metrics["split"]["test"]:
        assert test_id in held_out
    if name == "tactip_svm":
        assert f"| accuracy | {metrics['test']['accuracy']:.4g} |" in held_out
        assert (
            f"| majority_baseline_test | {metrics['majority_baseline_test']:.4g} |"
            in (held_out)
        )
    else:
        assert f"| events.tpr | {metrics['test']['events']['tpr']:.4g} |" in held_out
    point = card.split("## Operating point")[1].split("## Latency")[0]
    assert f"- Threshold: {manifest['threshold']:.4g}" in point
    assert f"- Debounce: {manifest['debounce']['k']} consecutive" in point
    assert metrics["operating_point"]["from"] in point


def test_card_gives_the_latency_with_cpu_and_onnxruntime(
    bundles: dict[str, tuple[Path, Path]],
) -> None:
    latency = _card(bundles["fsr"][1]).split("## Latency")[1].split("## ")[0]
    assert "- Loop p50 " in latency
    assert " us, p99 " in latency
    assert "against the budget p99 0.05 ms" in latency
    assert f"- CPU: {cpu_model()}; onnxruntime {onnxruntime.__version__}" in latency
    assert "first 50 replay frames" in latency


def test_card_without_a_timing_says_not_recorded(
    bundles: dict[str, tuple[Path, Path]],
) -> None:
    latency = _card(bundles["tactip_svm"][1]).split("## Latency")[1]
    assert f"- Loop p50 / p99: {NOT_RECORDED}" in latency
    assert "choose_session=false" in latency


def test_edited_card_fails_the_bundle_check(
    bundles: dict[str, tuple[Path, Path]], tmp_path: Path
) -> None:
    import shutil

    copy = tmp_path / "b"
    shutil.copytree(bundles["fsr"][1], copy)
    card = copy / CARD_FILE
    card.write_text(card.read_text().replace("simulated scenes only", "real data"))
    with pytest.raises(BundleError, match=r"MODEL_CARD\.md: sha256 .* does not match"):
        load_bundle(copy)


def test_licence_and_citation_of_known_sources() -> None:
    """The importers' licence and citation, from the provenance or, when it lacks them, the table."""
    full = data_source(
        {
            "source": bts3v2.SOURCE,
            "citation": bts3v2.CITATION,
            "license": bts3v2.LICENSE,
            "importer": "slipkit.data.importers.bts3v2.read_bts3v2",
        }
    )
    assert ("recorded", bts3v2.LICENSE, bts3v2.CITATION) == (
        full["kind"],
        full["license"],
        full["citation"],
    )
    bare = data_source(
        {"importer": "slipkit.data.importers.biotacsp_dos.read_biotacsp_dos"}
    )
    assert (biotacsp_dos.LICENSE, biotacsp_dos.CITATION, biotacsp_dos.SOURCE) == (
        bare["license"],
        bare["citation"],
        bare["source"],
    )
    own = data_source(
        {"source": "/lab/recordings", "importer": "slipkit.data.importers.csv.x"}
    )
    assert (None, None) == (own["license"], own["citation"])
    assert NOT_RECORDED == data_source({})["kind"]


def _fake_run(metrics: dict, tmp_path: Path, **task: str) -> SimpleNamespace:
    """What model_card reads of a run folder: run.json, metrics.json, config, the model."""
    return SimpleNamespace(
        path=tmp_path / "run",
        info={"model": "pkg.Model", "task": "pkg.Task", "name": "exp", "seed": 3},
        metrics=metrics,
        config=OmegaConf.create({"task": task}),
        model=object(),
    )


def test_card_of_an_imported_dataset_states_what_is_missing(tmp_path: Path) -> None:
    """A recording without licence in its provenance gets the known source's; what no
    source holds is "not recorded"; the objects never seen in training are counted."""
    dataset = make_dataset(n_trials=6, n_objects=6, with_events=False)
    dataset.provenance = {
        "importer": "slipkit.data.importers.biotacsp_dos.read_biotacsp_dos"
    }
    ids = [str(t) for t in dataset.trial_ids]
    metrics = {
        "split": {"by": "object", "train": ids[:4], "test": ids[4:]},
        "test": {"accuracy": 0.75, "recall": {"linear": 0.5}, "confusion": [[1]]},
        "controls": {"majority": {"window": {"accuracy": 0.5}}},
        "majority_accuracy": 0.5,
    }
    manifest = {
        "name": "b",
        "frame": {"streams": ["force"], "channels": ["fx"], "rate_hz": 300.0},
        "decision": {"rule": "argmax", "classes": ["a", "b"], "slip_classes": ["b"]},
        "training": {"scored_on": "the run's held-out test split", "held_out": True},
    }
    card = model_card(
        manifest,
        _fake_run(metrics, tmp_path, group="object"),
        dataset,
        kind="learned",
        latency=None,
        latency_note="none",
        debounce_from="the task's default",
        model_sha256="0" * 64,
    )
    assert f"- Licence: {biotacsp_dos.LICENSE}" in card
    assert f"- Citation: {biotacsp_dos.CITATION}" in card
    assert f"recordings of one source ({biotacsp_dos.SOURCE})" in card
    assert "simulated" not in card
    assert "| accuracy | 0.75 |" in card
    assert "| recall.linear | 0.5 |" in card
    assert "| controls.majority.accuracy | 0.5 |" in card
    assert "majority_accuracy" not in card  # the same figure as the block's
    assert "(group column `object`); 4 training / 2 test trials" in card
    assert "held out: obj4, obj5 (2 never seen in training)" in card
    assert f"- Operating point chosen by: {NOT_RECORDED}" in card
    assert f"- Loop p50 / p99: {NOT_RECORDED}" in card
    assert f"- Budget: frame period {NOT_RECORDED}, p99 <= {NOT_RECORDED}" in card


def test_card_of_a_time_block_split(tmp_path: Path) -> None:
    metrics = {
        "split": {
            "block_s": 4.0,
            "blocks": {"train": 6, "val": 2, "test": 2},
            "frames": {"train": 2400, "val": 800, "test": 800},
        },
    }
    card = model_card(
        {"name": "f", "frame": {}, "decision": {}, "training": {}},
        _fake_run(metrics, tmp_path),
        make_dataset(n_trials=2, with_events=False),
        kind="learned",
        latency=None,
        latency_note="none",
        debounce_from="x",
        model_sha256="0" * 64,
    )
    assert "- Split: by time blocks of 4 s; blocks: train 6, val 2, test 2;" in card
    assert f"Test metrics: {NOT_RECORDED}." in card
