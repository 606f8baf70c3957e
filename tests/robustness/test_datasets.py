"""Datasets: a corrupted byte anywhere in any file is refused, naming the file.

The field-by-field checks (missing or extra columns, wrong dtypes, truncated Parquet,
malformed or newer manifests, time going backwards) are in ``tests/data/test_dataset.py``.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from tests.strategies import make_dataset

from slipkit.data.io import load_dataset, save_dataset
from slipkit.errors import DatasetError

FILES = ("trials.parquet", "streams/force.parquet", "streams/events.parquet")


@pytest.fixture(scope="module")
def pristine(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return save_dataset(
        make_dataset(n_trials=2, n_frames=40), tmp_path_factory.mktemp("ds") / "ds"
    )


@settings(
    max_examples=30,
    deadline=None,
    suppress_health_check=[HealthCheck.function_scoped_fixture],
)
@given(
    rel=st.sampled_from(FILES),
    where=st.floats(0.0, 1.0, exclude_max=True),
    flip=st.integers(1, 255),
)
def test_any_flipped_byte_is_refused_naming_the_file(
    pristine: Path, tmp_path: Path, rel: str, where: float, flip: int
) -> None:
    """One byte XOR-ed anywhere in any Parquet file: load_dataset refuses it by sha256, naming that file."""
    ds = tmp_path / "copy"
    shutil.rmtree(ds, ignore_errors=True)
    shutil.copytree(pristine, ds)
    path = ds / rel
    data = bytearray(path.read_bytes())
    i = int(where * len(data))
    data[i] ^= flip
    path.write_bytes(bytes(data))
    with pytest.raises(DatasetError, match="sha256 mismatch") as info:
        load_dataset(ds)
    assert rel in str(info.value)
