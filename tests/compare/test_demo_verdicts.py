"""Verdicts are stable: two runs of the same comparison or demo give the same verdicts."""

from __future__ import annotations

from pathlib import Path

import pytest
from hydra import compose, initialize_config_dir

from slipkit import config_dir
from slipkit.compare.commands import comparison_seeds, run_comparison
from slipkit.compare.table import choose_deploy
from slipkit.demo import demo_main
from slipkit.errors import SlipkitError


def _compare_cfg(overrides: list[str]):  # type: ignore[no-untyped-def]
    with initialize_config_dir(config_dir=str(config_dir()), version_base="1.3"):
        return compose(config_name="compare", overrides=[*overrides, "progress=false"])


def test_seeds_option_wins_over_the_comparison_and_is_checked() -> None:
    """seeds= beats the comparison's seeds:, which beats seed; a repeated seed is refused."""
    cfg = _compare_cfg(["seed=4"])
    assert [4] == comparison_seeds(cfg, {})
    assert [1, 2] == comparison_seeds(cfg, {"seeds": [1, 2]})
    assert [0, 3] == comparison_seeds(_compare_cfg(["seeds=[0,3]"]), {"seeds": [1]})
    with pytest.raises(SlipkitError) as err:
        comparison_seeds(_compare_cfg(["seeds=[1,1]"]), {})
    assert "seeds=[1, 1]: a seed is listed twice" == str(err.value)


@pytest.mark.slow
def test_two_runs_of_a_seeded_comparison_give_one_verdict(tmp_path: Path) -> None:
    """The same comparison over seeds 0 and 1, run twice, recommends the same estimator."""
    cfg = _compare_cfg(
        [
            "comparison=tactip",
            "comparison.dataset.n_trials=6",
            "comparison.task_overrides.svm_rbf_tuned.search.n_trials=3",
            "seeds=[0,1]",
            "cost.max_frames=400",
        ]
    )
    verdicts = []
    for run in ("a", "b"):
        folder = tmp_path / run
        folder.mkdir()
        result = run_comparison(cfg, folder, progress=False)
        choice = choose_deploy(result.table)
        verdicts.append((str(choice.row["estimator"]), choice.recommended))
        assert [0, 1] == sorted(result.per_seed["seed"].unique().tolist())
    assert verdicts[0] == verdicts[1]


@pytest.mark.slow
def test_two_quick_demos_print_the_same_verdicts(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Two consecutive `slipkit demo quick=true` runs print the same family and verdict columns."""
    verdicts = []
    for run in ("a", "b"):
        with initialize_config_dir(config_dir=str(config_dir()), version_base="1.3"):
            cfg = compose(
                config_name="demo",
                overrides=[
                    "quick=true",
                    "progress=false",
                    f"out={tmp_path / run}",
                    f"data_root={tmp_path / 'no-real-data'}",
                    "~comparisons",
                    "+comparisons={tactip: [], biotac_slip: [], sliptack: []}",
                    "closedloop.enabled=false",
                ],
            )
            report = demo_main(cfg)
        printed = capsys.readouterr().out
        rows = [r.split("|") for r in report.read_text().splitlines()[4:7]]
        pairs = [(r[1].strip(), r[2].strip()) for r in rows]
        assert all(verdict in printed for _, verdict in pairs)
        verdicts.append(pairs)
    assert verdicts[0] == verdicts[1]
