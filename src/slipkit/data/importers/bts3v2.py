"""Importer of biotacsp-stability-set-v2: grasp stability, 3 x BioTac SP, snapshots.

Source layout (github.com/3dperceptionlab/biotacsp-stability-set-v2)::

    bts3v2/bts3v2_palm_down.csv       bts3v2_palm_side.csv       bts3v2_palm_45.csv
           bts3v2_palm_down_test.csv  bts3v2_palm_side_test.csv  bts3v2_palm_45_test.csv

The first three files are the published training set (41 objects), the ``_test`` ones
the published test set (10 further objects); either set, or both, may be present.

Each row is one grasp: ``object``, ``slipped`` (0 stable, 1 slipped on lifting),
then 72 electrode values (``ff_biotac_1..24``, ``mf_biotac_1..24``,
``th_biotac_1..24``) read once, before lifting. The hand orientation is in the
file name.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pandas as pd

from slipkit.data.dataset import Dataset, LabelSpec, StreamSpec
from slipkit.data.importers.csv import (
    check_header,
    line_of,
    numeric_block,
    read_csv_file,
)
from slipkit.errors import SourceFormatError

__all__ = ["CHANNELS", "CLASSES", "ORIENTATIONS", "SPLITS", "read_bts3v2"]

#: Fingers carrying a BioTac SP: first, middle, thumb.
FINGERS: tuple[str, ...] = ("ff", "mf", "th")
#: Electrode channels, as named in the files' header.
CHANNELS: tuple[str, ...] = tuple(
    f"{finger}_biotac_{i}" for finger in FINGERS for i in range(1, 25)
)
HEADER: tuple[str, ...] = ("object", "slipped", *CHANNELS)
#: Hand orientations, one file each.
ORIENTATIONS: tuple[str, ...] = ("palm_down", "palm_side", "palm_45")
#: Values of the trials column ``published_split``: from a training file, from a
#: ``_test`` file.
SPLITS: tuple[str, ...] = ("train", "test")
#: Classes of ``slip_class``: column ``slipped`` 0 and 1.
CLASSES: tuple[str, ...] = ("stable", "slipped")

SOURCE = "https://github.com/3dperceptionlab/biotacsp-stability-set-v2"
CITATION = (
    "Garcia-Garcia et al., 'TactileGCN: a graph convolutional network for "
    "predicting grasp stability with tactile sensors', IJCNN 2019"
)
LICENSE = "MIT (LICENSE file of the source repository)"

_FILE_NAME = re.compile(r"(?:^|_)(palm_(?:down|side|45))(_test)?$")


def _orientation(file: Path) -> tuple[str, str]:
    """(orientation, published split) from a file name."""
    match = _FILE_NAME.search(file.stem)
    if match is None:
        raise SourceFormatError(
            f"{file}: file name does not end in an orientation; expected "
            f"bts3v2_<orientation>.csv or bts3v2_<orientation>_test.csv with "
            f"<orientation> in {list(ORIENTATIONS)}"
        )
    return match.group(1), SPLITS[1] if match.group(2) else SPLITS[0]


def _list_files(path: Path) -> list[tuple[str, str, Path]]:
    """(orientation, split, file) of each CSV: training files first, each set in the
    order of :data:`ORIENTATIONS`."""
    if path.is_file():
        return [(*_orientation(path), path)]
    if not path.is_dir():
        raise SourceFormatError(f"{path}: no such file or folder")
    files = sorted(p for p in path.glob("*.csv") if p.is_file())
    if not files:
        raise SourceFormatError(
            f"{path}: no CSV files; expected bts3v2_palm_down.csv, "
            "bts3v2_palm_side.csv, bts3v2_palm_45.csv (and their _test files)"
        )
    seen: dict[tuple[str, str], Path] = {}
    for file in files:
        key = _orientation(file)
        if key in seen:
            raise SourceFormatError(
                f"{file}: orientation {key[0]!r} of the {key[1]} set is also the one "
                f"of {seen[key]}; expected one file per orientation and set"
            )
        seen[key] = file
    return [
        (o, split, seen[o, split])
        for split in SPLITS
        for o in ORIENTATIONS
        if (o, split) in seen
    ]


def read_bts3v2(path: Path | str) -> Dataset:
    """Read biotacsp-stability-set-v2 into a dataset: one trial per grasp (row).

    Parameters
    ----------
    path : path-like
        The folder holding ``bts3v2_palm_{down,side,45}.csv`` and / or the
        published test files ``bts3v2_palm_{down,side,45}_test.csv``, or one file.

    Returns
    -------
    Dataset
        Sensor ``biotac_sp_x3``; trial ids ``<orientation>/<row>`` (row: 0-based
        data row, 4 digits; ``<orientation>_test/<row>`` for a test file); trials
        column ``published_split`` (``train``, ``test``: the file's set); snapshot
        stream ``electrodes`` (72 channels as in the header, raw ADC counts,
        ``t = 0`` s); groups ``object`` and ``orientation``
        (palm_down, palm_side, palm_45); labels ``slip_class`` (stable, slipped:
        column ``slipped`` 0, 1) and ``slip_onset_s`` (s; NaN, not recorded).

    Raises
    ------
    SourceFormatError
        Naming the file (and line and column) of a wrong header, a ragged row, a
        value that is not a number, a ``slipped`` value other than 0 or 1, a
        missing object name, or a file name without an orientation.
    """
    path = Path(path)
    entries = _list_files(path)
    blocks: list[np.ndarray] = []
    trial_parts: list[pd.DataFrame] = []
    for orientation, split, file in entries:
        df = read_csv_file(file)
        check_header(file, df.columns, HEADER)
        if df.empty:
            raise SourceFormatError(f"{file}: has a header but no data rows")
        obj = df["object"]
        blank = (obj.isna() | (obj.astype(str).str.strip() == "")).to_numpy()
        if blank.any():
            row = int(np.flatnonzero(blank)[0])
            raise SourceFormatError(
                f"{file}: line {line_of(row)}, column 'object': missing object name"
            )
        slipped = numeric_block(file, df, ["slipped"])[:, 0]
        bad = np.flatnonzero((slipped != 0) & (slipped != 1))
        if len(bad):
            row = int(bad[0])
            raise SourceFormatError(
                f"{file}: line {line_of(row)}, column 'slipped': value "
                f"{slipped[row]:g}; expected 0 (stable) or 1 (slipped)"
            )
        blocks.append(numeric_block(file, df, CHANNELS))
        n = len(df)
        stem = orientation if split == SPLITS[0] else f"{orientation}_test"
        trial_parts.append(
            pd.DataFrame(
                {
                    "trial_id": [f"{stem}/{i:04d}" for i in range(n)],
                    "object": obj.astype(str).to_numpy(dtype=object),
                    "orientation": orientation,
                    "published_split": split,
                    "slip_class": np.asarray(CLASSES, dtype=object)[
                        slipped.astype(np.int64)
                    ],
                    "slip_onset_s": np.full(n, np.nan),
                }
            )
        )
    trials = pd.concat(trial_parts, ignore_index=True)
    table = pd.DataFrame(np.concatenate(blocks), columns=list(CHANNELS))
    table.insert(0, "t", 0.0)
    table.insert(0, "trial_id", trials["trial_id"].to_numpy())
    spec = StreamSpec(
        "electrodes",
        CHANNELS,
        dict.fromkeys(CHANNELS, "ADC"),
        rate_hz=None,
        kind="snapshot",
        description=(
            "BioTac SP electrodes of first finger (ff), middle finger (mf) and "
            "thumb (th), raw ADC counts, read once per grasp before lifting"
        ),
    )
    labels = {
        "slip_class": LabelSpec(
            "slip_class",
            classes=CLASSES,
            description="grasp outcome on lifting: stable (slipped=0) or slipped (1)",
        ),
        "slip_onset_s": LabelSpec(
            "slip_onset_s",
            unit="s",
            description="not recorded by the source: NaN here means unknown",
        ),
    }
    return Dataset(
        sensor="biotac_sp_x3",
        streams={"electrodes": spec},
        trials=trials,
        tables={"electrodes": table},
        labels=labels,
        groups=("object", "orientation"),
        provenance={
            "source": SOURCE,
            "citation": CITATION,
            "license": LICENSE,
            "importer": "slipkit.data.importers.bts3v2.read_bts3v2",
            "imported_from": str(path),
            "files": [file.name for _, _, file in entries],
        },
        name="bts3v2",
    )
