"""The slip-type task's figures and tables: accuracy against time into the trial, and the
per-width outputs of a window-width sweep.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd


def _pct(x: float | None) -> str:
    return "   n/a" if x is None or not np.isfinite(x) else f"{x * 100:5.1f} %"


def _plot_time(
    curve: pd.DataFrame,
    path: Path,
    *,
    origin: str,
    reference: tuple[str | None, float | None],
    published: Mapping[str, Any],
) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.0, 3.6))
    for col in curve.columns:
        if col.startswith("accuracy_"):
            ax.plot(
                curve["t_rel_s"] * 1000.0,
                curve[col] * 100.0,
                marker=".",
                label=col.removeprefix("accuracy_"),
            )
    if origin != "trial start":
        ax.axvline(0.0, color="k", lw=0.8, ls=":", label=origin)
    name, lag = reference
    if lag is not None:
        ax.axvline(lag * 1000.0, color="r", lw=1.0, label=f"{name} (median)")
    if published.get("accuracy") is not None:
        ax.axhline(
            float(published["accuracy"]) * 100.0,
            color="grey",
            lw=0.8,
            ls="--",
            label="published",
        )
    ax.set_xlabel(f"time of the window's last frame after {origin} (ms)")
    ax.set_ylabel("windows correct (%)")
    ax.set_ylim(0, 100)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def _width_outputs(table: pd.DataFrame, out: Path, unit: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    table.to_csv(out / "accuracy_vs_width.csv", index=False)
    fig, ax = plt.subplots(figsize=(5.0, 3.4))
    ax.plot(table["ms"], table["accuracy"] * 100.0, marker="o", label="per window")
    ax.plot(
        table["ms"],
        table["sequence_accuracy"] * 100.0,
        marker="s",
        label="per trial (vote)",
    )
    ax.set_xlabel("window length W (ms)")
    ax.set_ylabel("correct (%)")
    ax.set_ylim(0, 100)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out / "accuracy_vs_width.png", dpi=120)
    plt.close(fig)
