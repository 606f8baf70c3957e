"""``slipkit import`` and ``slipkit info``."""

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
from slipkit.errors import SourceFormatError


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
    # a chunk of trials at a time: memory does not grow with the recording (issue 17)
    info = summary_of_folder(Path(str(cfg.dataset)), verify=bool(cfg.verify))
    if cfg.json:
        print(json.dumps(info, indent=2, default=str))
    else:
        print(format_summary(info))
    return info
