"""Sim-to-real: the GelSight detectors trained on simulated trials, scored on real ones,
beside the same detectors trained on real trials (the report's nested CV).

``python -m slipkit.families.gelsight.sim2real --real <imported dataset> --sim <sim 0>
<sim 1> <sim 2> --seeds 0 1 2``

The simulated sets come from ``slipkit simulate scene=gelsight_grasp seed=<s>`` (one per
seed, or one for all seeds). For seed ``s`` every candidate of the report
(:func:`slipkit.families.gelsight.report.candidates`) chooses its setting and
threshold on the simulated set ``s`` alone, by the report's inner group k-fold over the
simulated objects (:func:`~slipkit.families.gelsight.report.choose_setting`), and is
refitted on the whole simulated set. It then scores every real trial once: nothing of
the real set is used to train or choose. The trained-on-real column is the report's
nested group CV over the real objects with the same seed, pooled over the held-out
folds, so both columns score the same 150 real trials. Each side also gives the
balanced accuracy on the real full-length trials alone
(:func:`~slipkit.families.gelsight.report.full_length`: where clip length carries no
label), the report's full-length column. Mean and sd over the seeds.
"""

from __future__ import annotations

import argparse
import json
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from slipkit.data.dataset import Dataset
from slipkit.errors import SlipkitError
from slipkit.families.gelsight.detectors import Trial
from slipkit.families.gelsight.importer import FINGERTIPS
from slipkit.families.gelsight.report import (
    candidates,
    check_json_out,
    choose_setting,
    evaluate,
    full_length,
    load_trials,
    pooled,
    write_json_out,
)

KEYS = (
    "balanced_accuracy",
    "balanced_accuracy_full_length",
    "slip_recall",
    "wiggle_false_alarm",
)


def _check_streams(real: Dataset, sim: Dataset, where: str) -> None:
    """The simulated set holds every fingertip stream the report reads of the real set."""
    missing = sorted(set(real.streams) - set(sim.streams) - {FINGERTIPS})
    if missing:
        raise SlipkitError(
            f"{where}: the simulated set lacks the real set's streams {missing}"
        )


Loaded = tuple[list[Trial], np.ndarray, np.ndarray, list[str]]


def sim_to_real(
    cand_name: str,
    sim: Loaded,
    real: Loaded,
    *,
    seed: int,
    arm: int = 12,
    inner: int = 4,
) -> dict[str, Any]:
    """One candidate trained and chosen on the simulated trials ``sim``, scored on every
    real trial (both as :func:`~slipkit.families.gelsight.report.load_trials` gives);
    ``balanced_accuracy_full_length`` over the real full-length trials alone."""
    cand = next(c for c in candidates(seed, arm) if c.name == cand_name)
    st, sy, sg, _ = sim
    rt, ry, _, _ = real
    label, det = choose_setting(cand, st, sy, sg, seed=seed, inner=inner)
    fired = np.zeros(len(ry), dtype=bool)
    first = np.full(len(ry), np.nan)
    for i, trial in enumerate(rt):
        a = det.alarm(trial)
        fired[i] = a is not None
        first[i] = np.nan if a is None else a
    return {**pooled(fired, first, ry, full_length(rt)), "chosen": label}


def _reported(report: dict[str, Any], name: str, seed: int) -> dict[str, Any]:
    """One seed's result of ``name`` in a report's JSON (``report --out``)."""
    seeds = report.get("seeds")
    row = report.get("results", {}).get(name)
    if seeds is None or row is None or seed not in seeds:
        raise SlipkitError(
            f"--real-report: no result of {name!r} for seed {seed} "
            f"(seeds {seeds}, detectors {sorted(report.get('results', {}))})"
        )
    result: dict[str, Any] = row["per_seed"][seeds.index(seed)]
    missing = [k for k in KEYS if k not in result]
    if missing:
        raise SlipkitError(
            f"--real-report: the result of {name!r} lacks {missing}: "
            "not the JSON of this version's report"
        )
    return result


def _stat(values: Sequence[float]) -> dict[str, float]:
    v = np.asarray(values, dtype=np.float64)
    if not np.isfinite(v).any():
        return {"mean": math.nan, "sd": math.nan}
    return {"mean": float(np.nanmean(v)), "sd": float(np.nanstd(v))}


def run(
    real: Dataset,
    sims: Sequence[Dataset],
    seeds: Sequence[int],
    names: Sequence[str] | None = None,
    *,
    arm: int = 12,
    real_report: dict[str, Any] | None = None,
    skip_real: bool = False,
) -> dict[str, Any]:
    """Every candidate over ``seeds``: trained on simulation and on real, side by side.

    ``real_report``: the report's results on ``real`` (``report --out``, same seeds),
    read for the trained-on-real column instead of running the nested CV again;
    ``skip_real``: leave that column out (NaN)."""
    if len(sims) not in (1, len(seeds)):
        raise SlipkitError(
            f"--sim: give one simulated set or one per seed ({len(seeds)}); got {len(sims)}"
        )
    for k, sim in enumerate(sims):
        _check_streams(real, sim, f"--sim #{k}")
    real_trials = load_trials(real)
    sim_trials = [load_trials(s) for s in sims]
    rt, ry, rg, _ = real_trials
    rows: dict[str, Any] = {}
    for cand in candidates(0, arm):
        if names and cand.name not in names:
            continue
        on_sim, on_real = [], []
        for k, seed in enumerate(seeds):
            loaded = sim_trials[k if len(sims) > 1 else 0]
            on_sim.append(
                sim_to_real(cand.name, loaded, real_trials, seed=seed, arm=arm)
            )
            if skip_real:
                continue
            if real_report is not None:
                on_real.append(_reported(real_report, cand.name, seed))
                continue
            c = next(c for c in candidates(seed, arm) if c.name == cand.name)
            on_real.append(evaluate(c, rt, ry, rg, seed=seed))
        rows[cand.name] = {
            "kind": cand.kind,
            "sim": {k: _stat([r[k] for r in on_sim]) for k in KEYS},
            "real": {k: _stat([r[k] for r in on_real] or [math.nan]) for k in KEYS},
            "sim_chosen": [r["chosen"] for r in on_sim],
            "per_seed": {"sim": on_sim, "real": on_real},
        }
        print(_row(cand.name, rows[cand.name]), flush=True)
    return {
        "real_trials": len(ry),
        "real_slip": int(ry.sum()),
        "sim_trials": [len(s.trials) for s in sims],
        "seeds": list(seeds),
        "results": rows,
    }


def _row(name: str, r: dict[str, Any]) -> str:
    def ms(side: str, k: str) -> str:
        if not math.isfinite(r[side][k]["mean"]):
            return "n/a"
        return f"{r[side][k]['mean']:.2f} ± {r[side][k]['sd']:.2f}"

    return (
        f"| {name} | {r['kind']} | {ms('sim', 'balanced_accuracy')} | "
        f"{ms('sim', 'balanced_accuracy_full_length')} | "
        f"{ms('sim', 'slip_recall')} | {ms('sim', 'wiggle_false_alarm')} | "
        f"{ms('real', 'balanced_accuracy')} | "
        f"{ms('real', 'balanced_accuracy_full_length')} |"
    )


HEADER = (
    "| detector | kind | trained on sim: balanced accuracy | full-length clips | "
    "slip recall | wiggle false alarms | trained on real: balanced accuracy | "
    "full-length clips |\n|---|---|---|---|---|---|---|---|"
)


def main(argv: Sequence[str] | None = None) -> None:
    from slipkit.data.io import load_dataset

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument(
        "--real", required=True, help="slipkit import source=gelsight output"
    )
    ap.add_argument(
        "--sim",
        nargs="+",
        required=True,
        help="slipkit simulate scene=gelsight_grasp outputs: one per seed, or one",
    )
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    ap.add_argument("--only", nargs="*", help="detector names (default: all)")
    ap.add_argument("--out", help="write the results as JSON here")
    ap.add_argument("--arm", type=int, default=12, help="as the report's --arm")
    ap.add_argument(
        "--real-report",
        help="the report's JSON on --real (report --out, same seeds and --arm): "
        "read the trained-on-real column from it instead of recomputing",
    )
    ap.add_argument(
        "--skip-real",
        action="store_true",
        help="leave the trained-on-real column out (the report gives it)",
    )
    args = ap.parse_args(argv)
    inputs: dict[str, str | None] = {
        "--real": args.real,
        "--real-report": args.real_report,
        **{f"--sim {p}": p for p in args.sim},
    }
    out = check_json_out(args.out, inputs)
    real = load_dataset(args.real)
    sims = [load_dataset(p) for p in args.sim]
    print(HEADER)
    reported = None
    if args.real_report:
        reported = json.loads(Path(args.real_report).read_text())
        if reported.get("trials") != len(real.trials):
            raise SlipkitError(
                f"{args.real_report}: {reported.get('trials')} trials, --real has "
                f"{len(real.trials)}: not the report of this dataset"
            )
    res = run(
        real,
        sims,
        args.seeds,
        args.only,
        arm=args.arm,
        real_report=reported,
        skip_real=args.skip_real,
    )
    if out is not None:
        write_json_out(out, res, inputs)


if __name__ == "__main__":  # pragma: no cover
    main()
