"""``slipkit demo``: the README's main job, on built-in defaults.

Simulates each default scene and imports the real recordings when they are present,
writes every dataset under ``out``, and prints their summaries and a closing table.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

from hydra import compose
from hydra.utils import instantiate
from omegaconf import DictConfig, OmegaConf

from slipkit.data.io import load_dataset, save_dataset
from slipkit.data.summary import summarize
from slipkit.sim.commands import build_scene


def demo_main(cfg: DictConfig) -> list[dict[str, Any]]:
    """Run the demo; return one row per dataset written (name, sensor, trials, rows, seconds)."""
    from tqdm import tqdm

    out = Path(str(cfg.out))
    rows: list[dict[str, Any]] = []
    for scene_name in tqdm(list(cfg.scenes), desc="simulate", unit="scene"):
        start = time.perf_counter()
        scene_cfg = compose(
            config_name="simulate", overrides=[f"scene={scene_name}"]
        ).scene
        scene = build_scene(scene_cfg)
        dataset = scene.simulate(
            int(cfg.n_trials),
            int(cfg.seed),
            config=OmegaConf.to_container(scene_cfg, resolve=True),
        )
        path = save_dataset(dataset, out / scene_name, overwrite=bool(cfg.overwrite))
        rows.append(_row(path, "simulated", time.perf_counter() - start))

    root = Path(str(cfg.data_root))
    present = {
        src: root / sub for src, sub in cfg.real.items() if (root / sub).exists()
    }
    if not present:
        print(
            f"real recordings not found under {root} (set SLIPKIT_DATA); skipping the import stage"
        )
    for source, src_path in tqdm(list(present.items()), desc="import", unit="source"):
        start = time.perf_counter()
        reader = instantiate(
            compose(
                config_name="import", overrides=[f"source={source}", "path=x", "out=x"]
            ).source
        )
        path = save_dataset(
            reader(src_path), out / source, overwrite=bool(cfg.overwrite)
        )
        rows.append(_row(path, "recorded", time.perf_counter() - start))

    for row in rows:
        print(f"\n== {row['dataset']} ({row['origin']})")
        print(summarize(load_dataset(row["path"])))
    print("\n" + _table(rows))
    print(out)
    return rows


def _row(path: Path, origin: str, seconds: float) -> dict[str, Any]:
    dataset = load_dataset(path)
    return {
        "dataset": path.name,
        "origin": origin,
        "sensor": dataset.sensor,
        "trials": len(dataset),
        "rows": sum(len(t) for t in dataset.tables.values()),
        "seconds": seconds,
        "path": path,
    }


def _table(rows: list[dict[str, Any]]) -> str:
    head = f"{'dataset':<22}{'origin':<11}{'sensor':<14}{'trials':>7}{'rows':>11}{'time (s)':>10}"
    lines = [head, "-" * len(head)]
    for r in rows:
        lines.append(
            f"{r['dataset']:<22}{r['origin']:<11}{r['sensor']:<14}{r['trials']:>7}{r['rows']:>11}{r['seconds']:>10.2f}"
        )
    return "\n".join(lines)
