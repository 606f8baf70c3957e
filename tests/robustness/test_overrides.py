"""Command-line overrides of a key the config does not know: one line naming it, exit 2.

With or without ``+``, an unknown key is refused before any work, with the closest
keys the config has; the config's real extension points (group appends, a keyword
of a ``_target_``, a new entry of a mapping of named entries) keep working.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from slipkit.cli import check_added_keys, main
from slipkit.errors import SlipkitError


@pytest.fixture(autouse=True)
def _sandbox(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Relative outputs and internal-error logs land under tmp_path only."""
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("SLIPKIT_LOG_DIR", str(tmp_path / "logs"))
    monkeypatch.setenv("SLIPKIT_DATA", str(tmp_path / "no-recordings"))
    monkeypatch.delenv("HYDRA_FULL_ERROR", raising=False)


def cli(args: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[Any, list[str]]:
    """(exit status, non-blank stderr lines) of ``slipkit <args>``; status 0 if it returned."""
    capsys.readouterr()
    try:
        main(args)
        code: Any = 0
    except SystemExit as exc:
        code = exc.code
    err = capsys.readouterr().err
    return code, [line for line in err.splitlines() if line.strip()]


@pytest.fixture
def recording(tmp_path: Path) -> Path:
    path = tmp_path / "rec.csv"
    path.write_text("t,a,slip\n0.0,1.0,0\n0.1,2.0,0\n", encoding="utf-8")
    return path


CASES: list[tuple[list[str], str]] = [
    (
        # a keyword the estimator takes but the config leaves unset: here + is the way
        [
            "compare",
            "comparison=fsr",
            "comparison.estimators.window_logreg.random_state=3",
            "out={tmp}/c",
        ],
        "slipkit compare: error: comparison.estimators.window_logreg.random_state: not "
        "set in the config; add it with +comparison.estimators.window_logreg.random_state=...",
    ),
    (
        [
            "import",
            "source=csv",
            "path={csv}",
            "out={tmp}/o",
            "source.label_column=[slip]",
        ],
        "slipkit import: error: source.label_column: unknown key; "
        "did you mean source.label_columns?",
    ),
    (
        [
            "import",
            "source=csv",
            "path={csv}",
            "out={tmp}/o",
            "+source.label_column=[slip]",
        ],
        "slipkit import: error: source.label_column: unknown key; "
        "did you mean source.label_columns?",
    ),
    (
        ["train", "+model.gama=0.01", "run_dir={tmp}/run"],
        "slipkit train: error: model.gama: unknown key; did you mean model.gamma?",
    ),
    (
        ["train", "++model.gama=0.01", "run_dir={tmp}/run"],
        "slipkit train: error: model.gama: unknown key; did you mean model.gamma?",
    ),
    (
        ["compare", "comparison=fsr", "+comparison.dataset.pth=/my/ds", "out={tmp}/c"],
        "slipkit compare: error: comparison.dataset.pth: unknown key; "
        "did you mean comparison.dataset.path?",
    ),
    (
        ["train", "+datset.path=/my/ds", "run_dir={tmp}/run"],
        "slipkit train: error: datset.path: unknown key; did you mean dataset?",
    ),
    (
        ["train", "dataset.path.x=1", "run_dir={tmp}/run"],
        "slipkit train: error: dataset.path.x: unknown key; dataset.path is one "
        "value, not a group of options",
    ),
]


@pytest.mark.parametrize(("args", "line"), CASES, ids=[" ".join(c[0]) for c in CASES])
def test_an_unknown_key_is_one_line_with_the_closest_keys(
    args: list[str],
    line: str,
    tmp_path: Path,
    recording: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    """An unknown key, with or without +, is one line naming it and the closest keys, exit 2, nothing written."""
    filled = [a.format(tmp=tmp_path, csv=recording) for a in args]
    before = sorted(p.name for p in tmp_path.iterdir())
    assert (2, [line]) == cli(filled, capsys)
    assert before == sorted(p.name for p in tmp_path.iterdir())


@pytest.mark.parametrize(
    ("command", "overrides"),
    [
        # a keyword the node's _target_ takes (WindowCNN's max_epochs)
        ("train", ["experiment=biotac_slip_type", "+task.compare.cnn.max_epochs=2"]),
        # a new entry of an empty mapping / a mapping of named entries
        ("train", ["experiment=biotac_slip_type", "+task.compare.mlp={_target_: x.Y}"]),
        ("demo", ["~comparisons", "+comparisons={fsr: []}"]),
        ("demo", ["+real.my_rig=my-rig"]),
        (
            "sweep",
            [
                "experiment=tactip_svm",
                "search=tactip_svm",
                "+search.params.model.CC={}",
            ],
        ),
        (
            "compare",
            ["comparison=fsr", "+comparison.scene.effects.drift={rate_per_s: 0.1}"],
        ),
        # a group append and Hydra's own settings
        ("train", ["+experiment=tactip_svm"]),
        ("train", ["+hydra.job.env_set.OMP_NUM_THREADS=1"]),
        # ++ on a key the config has
        ("simulate", ["scene=sliptack_pull", "++scene.model.rate_hz=500"]),
    ],
)
def test_extension_points_take_new_keys(command: str, overrides: list[str]) -> None:
    """Keys a config legitimately grows by (entries, target keywords, groups, hydra.*) pass the check."""
    check_added_keys(command, overrides)


def test_a_scene_effect_takes_its_own_keywords() -> None:
    """+scene.effects.<effect>.<keyword> passes for a keyword the effect takes, not for another."""
    check_added_keys(
        "simulate", ["scene=sliptack_pull", "+scene.effects.stick_slip.target=nib"]
    )
    with pytest.raises(SlipkitError) as refused:
        check_added_keys(
            "simulate", ["scene=sliptack_pull", "+scene.effects.stick_slip.M_k=1"]
        )
    assert (
        "scene.effects.stick_slip.M_k: unknown key; did you mean scene.effects.stick_slip.M_kg?"
        == str(refused.value)
    )


def test_a_multirun_with_an_unknown_key_starts_nothing(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """slipkit train -m +model.gama=1,2 is one line before Hydra makes its sweep folder."""
    code, err = cli(["train", "-m", "+model.gama=1,2", f"run_dir={tmp_path}/r"], capsys)
    assert (
        2,
        ["slipkit train: error: model.gama: unknown key; did you mean model.gamma?"],
        [],
    ) == (
        code,
        err,
        sorted(p.name for p in tmp_path.iterdir()),
    )
