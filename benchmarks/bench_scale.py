"""How time and memory grow with the data: per family, at 1x / 4x / 16x trials.

For each family a small base number of simulated trials is scaled by 1, 4 and 16, and
three real commands run, each in its own subprocess so its peak resident memory is its
own (``os.wait4`` rusage, ``ru_maxrss``):

- ``slipkit simulate`` (trials per second, stream rows per second),
- ``slipkit info`` on the written folder (rows per second; peak memory),
- ``slipkit train experiment=<family> dataset.path=<folder>`` (wall time; peak memory).

Then ``slipkit import`` throughput through the generic CSV importer (one CSV per trial
written from the 16x TacTip folder), and the TacTip SVM's super-linear fit time beside a
kernel approximation (scikit-learn ``Nystroem`` features + a logistic regression; the
``tactip_nystroem`` model config) on the same frames, with balanced accuracy on held-out
trials. Peak memory includes the interpreter and its imports (the import-only floors
printed first); the ratio 16x / 1x is the issue-17 target (at most 2 for
``info`` and for a window model's training). One run; other load on the machine shows.

    .venv/bin/python benchmarks/bench_scale.py                   # all families, a few minutes
    .venv/bin/python benchmarks/bench_scale.py --families tactip biotac_window
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

# family -> (experiment, base trials at 1x, extra train overrides keeping runs short)
FAMILIES: dict[str, tuple[str, int, list[str]]] = {
    "tactip": ("tactip_svm", 4, []),
    "biotac_window": (
        "biotac_slip_type",
        8,
        ["model.max_epochs=5", "task.first_frame_control=false", "task.dynamics=null"],
    ),
    "fsr": ("fsr_roc", 2, []),
    "sliptack": ("sliptack_speed", 6, []),
    "davis": ("davis_release", 4, []),
}
SCALES = (1, 4, 16)
THREADS = {"OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}


def slipkit(args: list[str], log: Path) -> tuple[float, float]:
    """Run ``slipkit <args>`` in a subprocess: (wall s, peak RSS MB). Exits on failure."""
    cmd = [sys.executable, "-c", "from slipkit.cli import main; main()", *args]
    env = {**os.environ, **THREADS}
    with open(log, "w", encoding="utf-8") as out:
        start = time.perf_counter()
        proc = subprocess.Popen(cmd, stdout=out, stderr=subprocess.STDOUT, env=env)
        _, status, usage = os.wait4(proc.pid, 0)
        wall = time.perf_counter() - start
    proc.returncode = os.waitstatus_to_exitcode(status)
    if proc.returncode != 0:
        sys.exit(
            f"bench_scale: slipkit {' '.join(args)} failed:\n{log.read_text()[-3000:]}"
        )
    return wall, usage.ru_maxrss / 1024.0  # Linux: kB


def floor_mb(code: str) -> float:
    """Peak RSS (MB) of a process that only runs ``code`` (imports)."""
    proc = subprocess.Popen([sys.executable, "-c", code], env={**os.environ, **THREADS})
    _, _, usage = os.wait4(proc.pid, 0)
    return usage.ru_maxrss / 1024.0


def rows_of(folder: Path) -> int:
    """Stream rows of a dataset folder (Parquet metadata only)."""
    import pyarrow.parquet as pq

    return sum(
        pq.ParquetFile(f).metadata.num_rows
        for f in (folder / "streams").glob("*.parquet")
    )


def family_rows(name: str, tmp: Path) -> list[dict[str, float | int | str]]:
    """simulate / info / train at every scale of one family."""
    experiment, base, extra = FAMILIES[name]
    scene = _experiment_scene(experiment)
    rows = []
    for k in SCALES:
        n = base * k
        data = tmp / f"{name}-{k}x"
        t_sim, m_sim = slipkit(
            [
                "simulate",
                f"scene={scene}",
                f"n_trials={n}",
                f"out={data}",
                "progress=false",
                "summary=false",
            ],
            tmp / "simulate.log",
        )
        n_rows = rows_of(data)
        t_info, m_info = slipkit(["info", f"dataset={data}"], tmp / "info.log")
        t_train, m_train = slipkit(
            [
                "train",
                f"experiment={experiment}",
                f"dataset.path={data}",
                f"runs_dir={tmp / 'runs'}",
                *extra,
            ],
            tmp / "train.log",
        )
        rows.append(
            {
                "family": name,
                "scale": f"{k}x",
                "trials": n,
                "rows": n_rows,
                "simulate_s": t_sim,
                "simulate_rows_per_s": n_rows / t_sim,
                "info_s": t_info,
                "info_mb": m_info,
                "train_s": t_train,
                "train_mb": m_train,
                "simulate_mb": m_sim,
            }
        )
        print(
            f"  {name} {k}x: {n} trials, {n_rows} rows; simulate {t_sim:.1f} s, "
            f"info {t_info:.1f} s / {m_info:.0f} MB, train {t_train:.1f} s / {m_train:.0f} MB",
            flush=True,
        )
    return rows


def _experiment_scene(experiment: str) -> str:
    """The scene an experiment's defaults override to (configs/experiment/<name>.yaml)."""
    from slipkit import config_dir

    text = (config_dir() / "experiment" / f"{experiment}.yaml").read_text()
    for line in text.splitlines():
        if "override /scene:" in line:
            return line.split(":", 1)[1].split("#")[0].strip()
    raise SystemExit(f"bench_scale: no scene override in experiment {experiment}")


def import_throughput(folder: Path, tmp: Path) -> dict[str, float]:
    """Write ``folder``'s pins as one CSV per trial, then time ``slipkit import``."""
    from slipkit.data import load_dataset

    ds = load_dataset(folder)
    raw = tmp / "csv"
    raw.mkdir()
    for trial in ds:
        # a lost pin is NaN; the generic importer wants numbers: 0 keeps the size
        trial.streams["pins"].fillna(0.0).to_csv(
            raw / f"{trial.trial_id}.csv", index=False
        )
    n_rows = int(sum(len(t) for t in [ds.tables["pins"]]))
    del ds
    wall, mb = slipkit(
        [
            "import",
            "source=csv",
            f"path={raw}",
            f"out={tmp / 'imported'}",
            "source.time_column=t",
            "source.sensor=tactip",
        ],
        tmp / "import.log",
    )
    return {"rows": n_rows, "import_s": wall, "rows_per_s": n_rows / wall, "mb": mb}


def svm_vs_nystroem(base_trials: int, seed: int = 0) -> list[dict[str, float | str]]:
    """Fit time and held-out balanced accuracy of the RBF SVM and Nystroem + linear model."""
    from hydra.utils import instantiate
    from omegaconf import OmegaConf
    from sklearn.metrics import balanced_accuracy_score

    from slipkit import config_dir
    from slipkit.families.tactip.features import dataset_features
    from slipkit.sim.commands import build_scene

    scene_cfg = OmegaConf.load(config_dir() / "scene" / "tactip_gravity_drop.yaml")
    svm_cfg = OmegaConf.load(config_dir() / "model" / "tactip_svm.yaml")
    nys_cfg = OmegaConf.load(config_dir() / "model" / "tactip_nystroem.yaml")
    out = []
    for k in SCALES:
        n = base_trials * k
        dataset = build_scene(scene_cfg).simulate(n_trials=2 * n, seed=seed)
        ids = dataset.trial_ids
        train = dataset_features(dataset.subset(ids[0::2]))
        test = dataset_features(dataset.subset(ids[1::2]))
        for label, cfg in (("rbf SVM", svm_cfg), ("Nystroem + linear", nys_cfg)):
            model = instantiate(cfg)
            start = time.perf_counter()
            model.fit(train.X, train.y)
            fit_s = time.perf_counter() - start
            acc = balanced_accuracy_score(test.y, model.predict(test.X))
            out.append(
                {
                    "scale": f"{k}x",
                    "frames": len(train.y),
                    "model": label,
                    "fit_s": fit_s,
                    "balanced_accuracy": float(acc),
                }
            )
            print(
                f"  {label} {k}x: {len(train.y)} frames, fit {fit_s:.2f} s, "
                f"balanced accuracy {acc:.3f}",
                flush=True,
            )
        del dataset, train, test
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--families", nargs="*", default=list(FAMILIES))
    parser.add_argument("--svm-trials", type=int, default=6, help="SVM base trials")
    parser.add_argument("--json", type=Path, help="also write the tables here")
    args = parser.parse_args()
    unknown = set(args.families) - set(FAMILIES)
    if unknown:
        sys.exit(
            f"bench_scale: unknown families {sorted(unknown)}; known: {list(FAMILIES)}"
        )
    print(f"{os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.1f} at start")
    result: dict[str, object] = {}
    with tempfile.TemporaryDirectory(prefix="bench-scale-") as tmp_name:
        tmp = Path(tmp_name)
        floor = {
            "info": floor_mb(
                "import slipkit.cli, slipkit.data.commands, pyarrow.parquet"
            ),
            "train": floor_mb("import slipkit.cli, slipkit.train.commands, torch"),
        }
        rows = []
        for name in args.families:
            rows.extend(family_rows(name, tmp))
        imp = (
            import_throughput(tmp / "tactip-16x", tmp)
            if "tactip" in args.families
            else None
        )
    nys = svm_vs_nystroem(args.svm_trials)
    result = {"floor_mb": floor, "families": rows, "import": imp, "svm": nys}

    print(
        f"\nimport-only floors (peak RSS): info's imports {floor['info']:.0f} MB, "
        f"train's with torch {floor['train']:.0f} MB"
    )
    print(
        "| family | scale | trials | rows | simulate s | simulate rows/s | info s | "
        "info MB | train s | train MB |"
    )
    print("|---|---|---:|---:|---:|---:|---:|---:|---:|---:|")
    for r in rows:
        print(
            f"| {r['family']} | {r['scale']} | {r['trials']} | {r['rows']} | "
            f"{r['simulate_s']:.1f} | {r['simulate_rows_per_s']:.0f} | {r['info_s']:.1f} | {r['info_mb']:.0f} | "
            f"{r['train_s']:.1f} | {r['train_mb']:.0f} |"
        )
    print("\npeak memory 16x / 1x (target <= 2 for info and window training):")
    for name in args.families:
        one = next(r for r in rows if r["family"] == name and r["scale"] == "1x")
        big = next(r for r in rows if r["family"] == name and r["scale"] == "16x")
        print(
            f"  {name}: info {big['info_mb'] / one['info_mb']:.2f}x, "
            f"train {big['train_mb'] / one['train_mb']:.2f}x, "
            f"train time {big['train_s'] / one['train_s']:.1f}x for 16x the trials"
        )
    if imp is not None:
        print(
            f"\nimport (generic CSV, {imp['rows']} rows): {imp['import_s']:.1f} s, "
            f"{imp['rows_per_s']:.0f} rows/s, {imp['mb']:.0f} MB peak"
        )
    print("\n| model | scale | training frames | fit s | held-out balanced accuracy |")
    print("|---|---|---:|---:|---:|")
    for r in nys:
        print(
            f"| {r['model']} | {r['scale']} | {r['frames']} | {r['fit_s']:.2f} | "
            f"{r['balanced_accuracy']:.3f} |"
        )
    print(f"load average at end: {os.getloadavg()[0]:.1f}")
    if args.json:
        args.json.write_text(json.dumps(result, indent=2) + "\n")


if __name__ == "__main__":
    main()
