"""``slipkit import``, ``slipkit info`` and ``slipkit export-dataset``."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

from hydra.utils import instantiate
from omegaconf import DictConfig

from slipkit._files import check_out_path
from slipkit.data.dataset import Dataset
from slipkit.data.io import save_dataset
from slipkit.data.summary import format_summary, summary_of_folder
from slipkit.errors import SlipkitError, SourceFormatError

#: ``slipkit export-dataset format=...``: the layouts written.
EXPORT_FORMATS = ("lerobot",)


def import_main(cfg: DictConfig) -> Path:
    """Read ``cfg.path`` with the importer ``cfg.source`` and write ``cfg.out``."""
    reader: Callable[..., Dataset] = instantiate(cfg.source)
    src = Path(str(cfg.path))
    if not src.exists():
        raise SourceFormatError(f"{src}: no such file or folder (path=...)")
    out = check_out_path(
        str(cfg.out),
        inputs={"path": src},
        kind="dataset",
        overwrite=bool(cfg.overwrite),
    )
    dataset = reader(src)
    out = save_dataset(dataset, out, overwrite=bool(cfg.overwrite))
    del dataset  # the summary re-reads the written folder a chunk at a time
    print(format_summary(summary_of_folder(out)))
    print(out)
    return out


def info_main(cfg: DictConfig) -> dict[str, Any]:
    """Print the summary of the dataset folder ``cfg.dataset``."""
    # a chunk of trials at a time: memory does not grow with the recording
    info = summary_of_folder(Path(str(cfg.dataset)), verify=bool(cfg.verify))
    if cfg.json:
        print(json.dumps(info, indent=2, default=str))
    else:
        print(format_summary(info))
    return info


def export_dataset_main(cfg: DictConfig) -> Path:
    """Write the dataset folder ``cfg.dataset`` in the layout ``cfg.format`` at ``cfg.out``."""
    from slipkit.data.lerobot import DEFAULT_FEATURES, write_lerobot

    fmt = str(cfg.format)
    if fmt not in EXPORT_FORMATS:
        raise SlipkitError(f"format={fmt}: expected one of {', '.join(EXPORT_FORMATS)}")
    out = write_lerobot(
        Path(str(cfg.dataset)),
        Path(str(cfg.out)),
        stream=None if cfg.stream is None else str(cfg.stream),
        feature=None if cfg.feature is None else str(cfg.feature),
        task=None if cfg.task is None else str(cfg.task),
        overwrite=bool(cfg.overwrite),
        verify=bool(cfg.verify),
    )
    info = json.loads((out / "meta" / "info.json").read_text(encoding="utf-8"))
    (key,) = [k for k in info["features"] if k not in DEFAULT_FEATURES]
    print(
        f"LeRobot {info['codebase_version']}: {info['total_episodes']} episodes, "
        f"{info['total_frames']} frames at {info['fps']} fps, feature {key} "
        f"({info['features'][key]['shape'][0]} channels)"
    )
    print(out)
    return out
