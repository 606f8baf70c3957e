"""Importer of BioTacSP-DoS: direction of slip on one BioTac SP, 24 electrodes.

Source layout (github.com/yayaneath/BioTacSP-DoS)::

    biotacsp-dos/csvs/<class>/<object><n>.csv    header ff_e1..ff_e24, no time column

``<class>`` is the direction of slip: ``n e s w`` translational (north, east,
south, west), ``cw aw`` rotational (clockwise, anti-clockwise), ``t`` touch
without slip. Each file is one sequence of about 3 s.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pandas as pd

from slipkit.data.dataset import Dataset, LabelSpec, StreamSpec
from slipkit.data.importers.csv import check_header, numeric_block, read_csv_file
from slipkit.errors import SourceFormatError

__all__ = ["CHANNELS", "CLASSES", "SLIP_TYPE", "SLIP_TYPES", "read_biotacsp_dos"]

#: Direction-of-slip classes, in the order of the source's paper.
CLASSES: tuple[str, ...] = ("n", "e", "s", "w", "cw", "aw", "t")
#: Slip type of each class (the linear-vs-rotational task, plus touch).
SLIP_TYPE: dict[str, str] = {
    "n": "linear",
    "e": "linear",
    "s": "linear",
    "w": "linear",
    "cw": "rotational",
    "aw": "rotational",
    "t": "touch",
}
SLIP_TYPES: tuple[str, ...] = ("linear", "rotational", "touch")
#: Electrode channels of the first finger's BioTac SP, as in the files' header.
CHANNELS: tuple[str, ...] = tuple(f"ff_e{i}" for i in range(1, 25))

SOURCE = "https://github.com/yayaneath/BioTacSP-DoS"
CITATION = (
    "Zapata-Impata, Gil, Torres, 'Learning spatio temporal tactile "
    "features with a ConvLSTM for the direction of slip detection', Sensors "
    "19(3):523, 2019"
)
LICENSE = (
    "no license file in the source repository; the authors ask to be cited in any "
    "result that uses the data"
)

_STEM = re.compile(r"(?P<object>.*?)(?P<number>\d*)")


def _csv_root(path: Path) -> Path:
    """The folder holding the class folders: ``path/csvs`` or ``path`` itself."""
    if not path.is_dir():
        raise SourceFormatError(
            f"{path}: not a folder; expected the BioTacSP-DoS folder holding "
            "csvs/<class>/<object><n>.csv"
        )
    return path / "csvs" if (path / "csvs").is_dir() else path


def _list_files(root: Path) -> list[tuple[str, Path]]:
    """(class, file) of every sequence, in class order, then object and number."""
    found: list[tuple[int, str, int, str, str, Path]] = []
    for folder in sorted(p for p in root.iterdir() if p.is_dir()):
        files = sorted(p for p in folder.glob("*.csv") if p.is_file())
        if not files:
            continue
        if folder.name not in CLASSES:
            raise SourceFormatError(
                f"{folder}: folder name {folder.name!r} is not a direction-of-slip "
                f"class; expected one of {list(CLASSES)}"
            )
        for file in files:
            match = _STEM.fullmatch(file.stem)
            assert match is not None  # the pattern matches every string
            obj, number = match["object"], match["number"]
            if not obj:
                raise SourceFormatError(
                    f"{file}: file name has no object name; expected <object><n>.csv"
                )
            found.append(
                (
                    CLASSES.index(folder.name),
                    obj,
                    int(number) if number else -1,
                    file.stem,
                    folder.name,
                    file,
                )
            )
    if not found:
        raise SourceFormatError(
            f"{root}: no CSV files in class folders; expected "
            f"csvs/<class>/<object><n>.csv with <class> in {list(CLASSES)}"
        )
    return [(cls, file) for *_, cls, file in sorted(found)]


def read_biotacsp_dos(path: Path | str, *, rate_hz: float = 100.0) -> Dataset:
    """Read BioTacSP-DoS into a dataset: one trial per sequence file.

    The files have no time column. The source describes its sequences as about
    100 Hz for 3 s (270-281 rows), so sample ``k`` of a sequence is placed at
    ``t = k / rate_hz`` seconds: an assumption, recorded in the provenance.

    Parameters
    ----------
    path : path-like
        The BioTacSP-DoS folder (holding ``csvs/``), or its ``csvs/`` folder.
    rate_hz : float
        Assumed sample rate in Hz (default 100 Hz, from the source's description).

    Returns
    -------
    Dataset
        Sensor ``biotac_sp``; trial ids ``<class>/<file stem>``; stream
        ``electrodes`` (``ff_e1..ff_e24``, raw ADC counts, sampled at ``rate_hz``);
        group ``object`` (the file stem without its trailing digits); labels
        ``slip_class`` (n, e, s, w, cw, aw, t: direction of slip), ``slip_type``
        (linear, rotational, touch) and ``slip_onset_s`` (s; NaN, not recorded).

    Raises
    ------
    SourceFormatError
        Naming the file (and line and column) of a wrong header, a ragged row, a
        value that is not a number, an empty sequence, or a folder that is not a
        class.
    """
    path = Path(path)
    spec = StreamSpec(
        "electrodes",
        CHANNELS,
        dict.fromkeys(CHANNELS, "ADC"),
        rate_hz=float(rate_hz),
        kind="sampled",
        description="BioTac SP electrode impedances, raw ADC counts (about 2500-3700)",
    )
    root = _csv_root(path)
    entries = _list_files(root)
    blocks: list[np.ndarray] = []
    rows: list[dict[str, object]] = []
    for cls, file in entries:
        df = read_csv_file(file)
        check_header(file, df.columns, CHANNELS)
        if df.empty:
            raise SourceFormatError(f"{file}: has a header but no data rows")
        blocks.append(numeric_block(file, df, CHANNELS))
        rows.append(
            {
                "trial_id": f"{cls}/{file.stem}",
                "object": file.stem.rstrip("0123456789"),
                "slip_class": cls,
                "slip_type": SLIP_TYPE[cls],
                "slip_onset_s": np.nan,
            }
        )
    lengths = np.array([len(b) for b in blocks])
    starts = np.repeat(np.cumsum(lengths) - lengths, lengths)
    table = pd.DataFrame(np.concatenate(blocks), columns=list(CHANNELS))
    table.insert(0, "t", (np.arange(len(table)) - starts) / float(rate_hz))
    table.insert(0, "trial_id", np.repeat([r["trial_id"] for r in rows], lengths))
    labels = {
        "slip_class": LabelSpec(
            "slip_class",
            classes=CLASSES,
            description=(
                "direction of slip: n e s w translational (north, east, south, "
                "west), cw aw rotational (clockwise, anti-clockwise), t touch "
                "without slip"
            ),
        ),
        "slip_type": LabelSpec(
            "slip_type",
            classes=SLIP_TYPES,
            description="linear (n e s w), rotational (cw aw) or touch (t)",
        ),
        "slip_onset_s": LabelSpec(
            "slip_onset_s",
            unit="s",
            description="not recorded by the source: NaN here means unknown",
        ),
    }
    return Dataset(
        sensor="biotac_sp",
        streams={"electrodes": spec},
        trials=pd.DataFrame(rows),
        tables={"electrodes": table},
        labels=labels,
        groups=("object",),
        provenance={
            "source": SOURCE,
            "citation": CITATION,
            "license": LICENSE,
            "assumptions": [
                f"sample rate {float(rate_hz):g} Hz assumed (t = row / rate_hz): the "
                "files have no time column; the source describes about 100 Hz for "
                "3 s"
            ],
            "rate_hz": float(rate_hz),
            "importer": "slipkit.data.importers.biotacsp_dos.read_biotacsp_dos",
            "imported_from": str(path),
            "files": [file.relative_to(root).as_posix() for _, file in entries],
        },
        name="biotacsp_dos",
    )
