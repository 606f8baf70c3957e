"""Trials, datasets, their on-disk format, splits and importers of real recordings."""

from slipkit.data.dataset import (
    FORMAT,
    SCHEMA_VERSION,
    Dataset,
    LabelSpec,
    StreamSpec,
    Trial,
)
from slipkit.data.io import load_dataset, read_manifest, save_dataset
from slipkit.data.splits import (
    BlockSplit,
    TrialSplit,
    split_by_group,
    split_by_trial,
    split_time_blocks,
    time_blocks,
)
from slipkit.data.summary import summarize

__all__ = [
    "FORMAT",
    "SCHEMA_VERSION",
    "BlockSplit",
    "Dataset",
    "LabelSpec",
    "StreamSpec",
    "Trial",
    "TrialSplit",
    "load_dataset",
    "read_manifest",
    "save_dataset",
    "split_by_group",
    "split_by_trial",
    "split_time_blocks",
    "summarize",
    "time_blocks",
]
