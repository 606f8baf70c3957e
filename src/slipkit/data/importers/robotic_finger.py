"""Importer of Robotic-Finger: BioTac electrodes and the contact force direction.

Source layout (github.com/Alexis-Georganopoulos/Robotic-Finger)::

    robotic-finger/X1.txt   19 rows (mean-centred electrode values) x N columns
    robotic-finger/Y1.txt    3 rows (unit force direction x, y, z)  x N columns

Whitespace-separated; one column per sample, so both are transposed. The author's
filtering lost the time order, so every sample is its own trial.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from slipkit.data.dataset import Dataset, StreamSpec
from slipkit.errors import SourceFormatError

__all__ = ["DIRECTION", "ELECTRODES", "read_robotic_finger"]

#: Electrode channels (rows of ``X1.txt``).
ELECTRODES: tuple[str, ...] = tuple(f"e{i}" for i in range(1, 20))
#: Force-direction channels (rows of ``Y1.txt``).
DIRECTION: tuple[str, ...] = ("ux", "uy", "uz")

SOURCE = "https://github.com/Alexis-Georganopoulos/Robotic-Finger"
LICENSE = "GPL-3.0 (LICENSE.md of the source repository)"


def _read_matrix(file: Path, n_rows: int, what: str) -> np.ndarray:
    """A whitespace-separated matrix of ``n_rows`` rows, every value finite.

    Raises
    ------
    SourceFormatError
        Naming the file, and the line (1-based) and column (1-based) at fault.
    """
    try:
        text = file.read_text(encoding="utf-8")
    except FileNotFoundError as exc:
        raise SourceFormatError(f"{file}: no such file") from exc
    except UnicodeDecodeError as exc:
        raise SourceFormatError(f"{file}: is not a text file ({exc})") from exc
    lines = text.splitlines()
    while lines and not lines[-1].strip():
        lines.pop()
    if len(lines) != n_rows:
        raise SourceFormatError(
            f"{file}: has {len(lines)} rows; expected {n_rows} ({what}, one row each)"
        )
    rows: list[np.ndarray] = []
    for number, line in enumerate(lines, start=1):
        tokens = line.split()
        try:
            row = np.array(tokens, dtype=np.float64)
        except ValueError:
            for col, token in enumerate(tokens, start=1):
                try:
                    float(token)
                except ValueError:
                    raise SourceFormatError(
                        f"{file}: line {number}, column {col}: {token!r} is not a "
                        "number"
                    ) from None
            raise
        if rows and len(row) != len(rows[0]):
            raise SourceFormatError(
                f"{file}: line {number} has {len(row)} values; line 1 has "
                f"{len(rows[0])} (ragged rows: every row needs one value per sample)"
            )
        bad = np.flatnonzero(~np.isfinite(row))
        if len(bad):
            raise SourceFormatError(
                f"{file}: line {number}, column {int(bad[0]) + 1}: non-finite value "
                f"{tokens[int(bad[0])]!r}"
            )
        rows.append(row)
    if not len(rows[0]):
        raise SourceFormatError(f"{file}: has no samples (empty rows)")
    return np.stack(rows)


def read_robotic_finger(path: Path | str, *, unit_tol: float = 1e-3) -> Dataset:
    """Read Robotic-Finger into a dataset: one trial per sample.

    Parameters
    ----------
    path : path-like
        The folder holding ``X1.txt`` and ``Y1.txt``.
    unit_tol : float
        Largest accepted ``| |u| - 1 |`` of a force direction (dimensionless).

    Returns
    -------
    Dataset
        Sensor ``biotac``; trial ids ``sample<k>`` (``k``: 0-based column of the
        source files, 4 digits; also in the trials column ``sample``); snapshot
        streams ``electrodes`` (``e1..e19``, mean-centred ADC counts) and
        ``truth_force_dir`` (``ux, uy, uz``, unit vector, unit ``"1"``), each at
        ``t = 0`` s. No labels or groups: there is no force magnitude, object or
        time order.

    Raises
    ------
    SourceFormatError
        Naming the file (and line and column) of a missing file, a wrong number
        of rows, ragged rows, a value that is not a number, column counts that
        disagree between the files, or a direction that is not a unit vector.
    """
    path = Path(path)
    if not path.is_dir():
        raise SourceFormatError(
            f"{path}: not a folder; expected the folder holding X1.txt and Y1.txt"
        )
    x_file, y_file = path / "X1.txt", path / "Y1.txt"
    x = _read_matrix(x_file, len(ELECTRODES), "electrodes e1..e19").T
    y = _read_matrix(y_file, len(DIRECTION), "force direction x, y, z").T
    if len(x) != len(y):
        raise SourceFormatError(
            f"{y_file}: has {len(y)} columns (samples) but {x_file} has {len(x)}; "
            "expected one column per sample in both"
        )
    norm = np.linalg.norm(y, axis=1)
    off = np.flatnonzero(np.abs(norm - 1.0) > unit_tol)
    if len(off):
        k = int(off[0])
        raise SourceFormatError(
            f"{y_file}: column {k + 1} (sample {k}) has norm {float(norm[k])}; "
            f"expected a unit vector (| |u| - 1 | <= {unit_tol:g})"
        )
    n = len(x)
    ids = np.array([f"sample{k:04d}" for k in range(n)], dtype=object)
    tables = {}
    for name, values, channels in (
        ("electrodes", x, ELECTRODES),
        ("truth_force_dir", y, DIRECTION),
    ):
        table = pd.DataFrame(values, columns=list(channels))
        table.insert(0, "t", 0.0)
        table.insert(0, "trial_id", ids)
        tables[name] = table
    streams = {
        "electrodes": StreamSpec(
            "electrodes",
            ELECTRODES,
            dict.fromkeys(ELECTRODES, "ADC (mean-centred)"),
            rate_hz=None,
            kind="snapshot",
            description="BioTac electrode values, mean-centred by the source's author",
        ),
        "truth_force_dir": StreamSpec(
            "truth_force_dir",
            DIRECTION,
            dict.fromkeys(DIRECTION, "1"),
            rate_hz=None,
            kind="snapshot",
            description="unit vector of the contact force direction (no magnitude)",
        ),
    }
    return Dataset(
        sensor="biotac",
        streams=streams,
        trials=pd.DataFrame({"trial_id": ids, "sample": np.arange(n)}),
        tables=tables,
        provenance={
            "source": SOURCE,
            "license": LICENSE,
            "assumptions": [
                "samples are independent: the time order was lost when the author "
                "filtered the data"
            ],
            "importer": "slipkit.data.importers.robotic_finger.read_robotic_finger",
            "imported_from": str(path),
            "files": [x_file.name, y_file.name],
        },
        name="robotic_finger",
    )
