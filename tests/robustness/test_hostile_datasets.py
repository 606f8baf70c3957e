"""Hostile datasets (issue 12): manifests, dataset folders and CSV files crafted to break
the reader end in one ``SlipkitError`` line naming the file and the field, line or column.

Each case was accepted silently, or ended in a Python traceback, before issue 12.
"""

from __future__ import annotations

import json
import math
import shutil
from collections.abc import Callable
from pathlib import Path
from typing import Any

import jsonschema
import pandas as pd
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from tests.strategies import make_dataset

from slipkit._files import sha256_file
from slipkit.cli import main
from slipkit.data import SCHEMA_VERSION, load_dataset, save_dataset
from slipkit.data._manifest import MAX_DEPTH, MAX_MANIFEST_BYTES, manifest_schema
from slipkit.data.importers import read_csv_dataset
from slipkit.errors import SlipkitError, SourceFormatError

ROOT = Path(__file__).resolve().parents[2]
SCHEMA_FILE = ROOT / "src/slipkit/data/schema/dataset-manifest.schema.json"

RATE = "a positive number (Hz, at most 1e9) for a sampled stream"
N_TRIALS = "a whole number of trials >= 1"
NAME = "a non-empty name without '/', '\\' or control characters"
COLUMN = (
    "a non-empty column name other than 'trial_id' and 't', without control characters"
)
CHANNEL = (
    "a non-empty channel name other than 'trial_id' and 't', without control characters"
)
STREAM = "a stream entry (an object with kind, rate_hz, channels, units)"
LABEL = "a label entry (an object with unit or classes, and description)"
RELPATH = (
    "a relative path inside the dataset folder (no leading '/', no '..', '.' or "
    "empty part, no '\\')"
)


# -- a small valid dataset, written once ---------------------------------------------


@pytest.fixture(scope="module")
def pristine(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A valid two-stream dataset (3 trials: force at 300 Hz, events)."""
    return save_dataset(
        make_dataset(n_trials=3, n_frames=20), tmp_path_factory.mktemp("ds") / "ds"
    )


@pytest.fixture
def ds(pristine: Path, tmp_path: Path) -> Path:
    """A private copy of the valid dataset to damage."""
    return Path(shutil.copytree(pristine, tmp_path / "ds"))


def _manifest(path: Path) -> dict[str, Any]:
    return json.loads((path / "manifest.json").read_text())


def _write_manifest(path: Path, manifest: Any) -> None:
    (path / "manifest.json").write_text(json.dumps(manifest))


def _error(path: Path) -> str:
    """The one-line message load_dataset refuses ``path`` with."""
    with pytest.raises(SlipkitError) as info:
        load_dataset(path)
    return str(info.value)


def _edit(path: Path, edit: Callable[[dict[str, Any]], None]) -> None:
    manifest = _manifest(path)
    edit(manifest)
    _write_manifest(path, manifest)


def _set(*keys: Any, value: Any) -> Callable[[dict[str, Any]], None]:
    def edit(manifest: dict[str, Any]) -> None:
        node = manifest
        for key in keys[:-1]:
            node = node[key]
        node[keys[-1]] = value

    return edit


# -- manifest fields: each one line naming the field path ------------------------------

FIELD_CASES = [
    # (test id, edit, message after "<ds>/manifest.json: ")
    (
        "rate_hz-true",
        _set("streams", "force", "rate_hz", value=True),
        f"streams.force.rate_hz: expected {RATE}, got true",
    ),
    (
        "rate_hz-text-2000",
        _set("streams", "force", "rate_hz", value="2000"),
        f'streams.force.rate_hz: expected {RATE}, got "2000"',
    ),
    (
        "rate_hz-text-abc",
        _set("streams", "force", "rate_hz", value="abc"),
        f'streams.force.rate_hz: expected {RATE}, got "abc"',
    ),
    (
        "rate_hz-NaN",
        _set("streams", "force", "rate_hz", value=math.nan),
        f"streams.force.rate_hz: expected {RATE}, got NaN",
    ),
    (
        "rate_hz-1e12",
        _set("streams", "force", "rate_hz", value=1e12),
        f"streams.force.rate_hz: expected {RATE}, got 1000000000000.0",
    ),
    (
        "n_trials-three",
        _set("n_trials", value="three"),
        f'n_trials: expected {N_TRIALS}, got "three"',
    ),
    (
        "n_trials-minus3",
        _set("n_trials", value=-3),
        f"n_trials: expected {N_TRIALS}, got -3",
    ),
    (
        "n_trials-1e18",
        _set("n_trials", value=1e18),
        f"n_trials: expected {N_TRIALS}, got 1e+18",
    ),
    (
        "n_trials-10e18-int",
        _set("n_trials", value=10**18),
        "field 'n_trials' is 1000000000000000000, but trials.parquet has 3 rows",
    ),
    (
        "sensor-empty",
        _set("sensor", value=""),
        f'sensor: expected {NAME}, got ""',
    ),
    (
        "channel-bool",
        _set("streams", "force", "channels", value=["fx", "fy", True]),
        f"streams.force.channels[2]: expected {CHANNEL}, got true",
    ),
    (
        "stream-number",
        _set("streams", "force", value=3),
        f"streams.force: expected {STREAM}, got 3",
    ),
    (
        "units-list",
        _set("streams", "force", "units", value=["N", "N", "N"]),
        "streams.force.units: expected an object mapping each channel to its unit, "
        "got a list of 3",
    ),
    (
        "units-extra",
        _set(
            "streams", "force", "units", value={c: "N" for c in ["fx", "fy", "fz", "q"]}
        ),
        "streams.force.units: gives units for ['q'], which are not among its "
        "channels ['fx', 'fy', 'fz']",
    ),
    (
        "label-string",
        _set("labels", "slip_class", value="linear"),
        f'labels.slip_class: expected {LABEL}, got "linear"',
    ),
    (
        "digest-int",
        _set("files", "trials.parquet", value=5),
        'files["trials.parquet"]: expected a sha256 digest as 64 lowercase hex '
        "digits, got 5",
    ),
    (
        "groups-object",
        _set("groups", value=[{}]),
        f"groups[0]: expected {COLUMN}, got an object",
    ),
    (
        "groups-trial_id",
        _set("groups", value=["trial_id"]),
        f'groups[0]: expected {COLUMN}, got "trial_id"',
    ),
    (
        "stream-extra-field",
        _set("streams", "force", "rate", value=300.0),
        "streams.force: unexpected field 'rate'; expected fields ['channels', "
        "'description', 'kind', 'rate_hz', 'units']",
    ),
    (
        "label-extra-field",
        _set("labels", "slip_class", "clases", value=["a"]),
        "labels.slip_class: unexpected field 'clases'; expected fields "
        "['classes', 'description', 'unit']",
    ),
    (
        "events-rate",
        _set("streams", "events", "rate_hz", value=5),
        "streams.events.rate_hz: expected null (events and snapshot streams have no "
        "rate), got 5",
    ),
    (
        "files-dotdot",
        _set("files", "../../../etc/passwd", value="0" * 64),
        f'files: key "../../../etc/passwd": expected {RELPATH}',
    ),
    (
        "files-absolute",
        _set("files", "/etc/passwd", value="0" * 64),
        f'files: key "/etc/passwd": expected {RELPATH}',
    ),
]


@pytest.mark.parametrize(
    ("edit", "message"),
    [pytest.param(edit, msg, id=name) for name, edit, msg in FIELD_CASES],
)
def test_bad_manifest_field_is_one_line_naming_the_field(
    ds: Path, edit: Callable[[dict[str, Any]], None], message: str
) -> None:
    """A wrong type, range or name in manifest.json is a DatasetError naming its field path."""
    _edit(ds, edit)
    assert f"{ds}/manifest.json: {message}" == _error(ds)


def test_duplicate_json_keys_are_refused(ds: Path) -> None:
    """A key given twice in one JSON object (json.loads would keep the last) is refused."""
    text = (ds / "manifest.json").read_text()
    text = text.replace('"sensor": "biotac",', '"sensor": "biotac", "sensor": "fsr",')
    (ds / "manifest.json").write_text(text)
    assert (
        f"{ds}/manifest.json: key 'sensor' appears twice in one JSON object; each "
        "field once"
    ) == _error(ds)


@pytest.mark.parametrize("depth", [MAX_DEPTH + 1, 100_000])
def test_deeply_nested_json_is_refused(ds: Path, depth: int) -> None:
    """Nesting past MAX_DEPTH is refused; past Python's recursion limit too (no RecursionError)."""
    manifest = _manifest(ds)
    text = json.dumps(manifest).replace(
        '"provenance": {',
        '"provenance": {"junk": ' + "[" * depth + "]" * depth + ", ",
        1,
    )
    (ds / "manifest.json").write_text(text)
    expected = {
        MAX_DEPTH + 1: f"nests JSON objects or lists deeper than {MAX_DEPTH} levels",
        100_000: f"nests JSON deeper than Python can parse; at most {MAX_DEPTH} levels",
    }[depth]
    assert f"{ds}/manifest.json: {expected}" == _error(ds)


def test_integer_beyond_pythons_digit_limit_is_refused(ds: Path) -> None:
    """A 5000-digit integer (Python's int parser stops at 4300 digits) is a DatasetError."""
    text = json.dumps(_manifest(ds)).replace(
        '"n_trials": 3', '"n_trials": ' + "9" * 5000
    )
    (ds / "manifest.json").write_text(text)
    assert _error(ds).startswith(
        f"{ds}/manifest.json: is not valid JSON (Exceeds the limit (4300 digits)"
    )


def test_nesting_at_the_cap_still_loads(ds: Path) -> None:
    """Provenance nested exactly MAX_DEPTH levels deep (top level included) loads."""
    manifest = _manifest(ds)
    junk: Any = []
    for _ in range(MAX_DEPTH - 3):  # top level, provenance, then MAX_DEPTH - 2 lists
        junk = [junk]
    manifest["provenance"] = {"junk": junk}
    _write_manifest(ds, manifest)
    assert {"junk": junk} == load_dataset(ds).provenance


def test_oversized_manifest_is_refused_before_parsing(ds: Path) -> None:
    """A valid but > 64 MiB manifest (whitespace padding) is refused by its size."""
    text = (ds / "manifest.json").read_text()
    padded = text + " " * (MAX_MANIFEST_BYTES + 1 - len(text.encode()))
    (ds / "manifest.json").write_text(padded)
    assert (
        f"{ds}/manifest.json: is {MAX_MANIFEST_BYTES + 1} bytes; a manifest is at "
        f"most {MAX_MANIFEST_BYTES} bytes"
    ) == _error(ds)


def test_integer_fields_refuse_floats_and_bools(ds: Path) -> None:
    """schema_version 1.0 and true are not the integer 1 (JSON Schema alone accepts 1.0)."""
    for value, shown in [(1.0, "1.0"), (True, "true")]:
        manifest = _manifest(ds)
        manifest["schema_version"] = value
        _write_manifest(ds, manifest)
        assert (
            f"{ds}/manifest.json: schema_version: expected the integer 1, got {shown}"
        ) == _error(ds)


# -- files that lie outside the dataset folder -----------------------------------------


def _outside_copy(ds: Path, rel: str) -> Path:
    """A copy of ``ds/rel`` beside the dataset folder, outside it."""
    out = ds.parent / "outside" / Path(rel).name
    out.parent.mkdir(exist_ok=True)
    shutil.copy(ds / rel, out)
    return out


def test_files_entry_climbing_out_with_dotdot_is_refused(ds: Path) -> None:
    """A files entry '../outside/...' with a matching sha256 is never read."""
    out = _outside_copy(ds, "trials.parquet")
    manifest = _manifest(ds)
    manifest["files"]["../outside/trials.parquet"] = sha256_file(out)
    _write_manifest(ds, manifest)
    assert (
        f'{ds}/manifest.json: files: key "../outside/trials.parquet": expected {RELPATH}'
    ) == _error(ds)


def test_symlinked_stream_pointing_outside_is_refused(ds: Path) -> None:
    """streams/force.parquet as a symlink to a (matching) file outside the folder is refused."""
    out = _outside_copy(ds, "streams/force.parquet")
    (ds / "streams/force.parquet").unlink()
    (ds / "streams/force.parquet").symlink_to(out)
    assert (
        f"{ds}/streams/force.parquet: resolves to {out.resolve()}, outside the dataset "
        f"folder {ds.resolve()}; every file of a dataset must lie inside its folder "
        "(no '..', absolute path, or symlink pointing out)"
    ) == _error(ds)


def test_symlinked_streams_folder_pointing_outside_is_refused(ds: Path) -> None:
    """A streams/ folder that is a symlink to a folder outside is refused, naming a file in it."""
    outside = ds.parent / "outside_streams"
    shutil.move(ds / "streams", outside)
    (ds / "streams").symlink_to(outside)
    assert (
        f"{ds}/streams/events.parquet: resolves to {outside.resolve()}/events.parquet, "
        f"outside the dataset folder {ds.resolve()}; every file of a dataset must lie "
        "inside its folder (no '..', absolute path, or symlink pointing out)"
    ) == _error(ds)


def test_symlinked_manifest_pointing_outside_is_refused(ds: Path) -> None:
    """manifest.json itself as a symlink to a file outside the folder is refused."""
    out = _outside_copy(ds, "manifest.json")
    (ds / "manifest.json").unlink()
    (ds / "manifest.json").symlink_to(out)
    assert _error(ds).startswith(
        f"{ds}/manifest.json: resolves to {out.resolve()}, outside the dataset folder"
    )


def test_symlink_inside_the_folder_still_loads(ds: Path) -> None:
    """A symlink to another file inside the dataset folder is allowed (it stays inside)."""
    real = ds / "streams" / "force.real"
    (ds / "streams/force.parquet").rename(real)
    (ds / "streams/force.parquet").symlink_to(real)
    assert 3 == len(load_dataset(ds))


# -- table contents --------------------------------------------------------------------


def _rewrite(path: Path, rel: str, df: pd.DataFrame) -> None:
    """Replace a table and fix its checksum, so only the content check can fail."""
    df.to_parquet(path / rel, index=False)
    manifest = _manifest(path)
    manifest["files"][rel] = sha256_file(path / rel)
    _write_manifest(path, manifest)


def test_text_in_a_numeric_label_is_refused(ds: Path) -> None:
    """slip_onset_s 'soon' in trials.parquet (the manifest says seconds) names column and row."""
    trials = pd.read_parquet(ds / "trials.parquet")
    trials["slip_onset_s"] = ["0.5", "soon", ""]
    _rewrite(ds, "trials.parquet", trials)
    assert (
        f"{ds}/trials.parquet: column 'slip_onset_s' holds 'soon' at row 1; the "
        "manifest declares label 'slip_onset_s' numeric (unit 's', no classes), so "
        "every value must be a number or NaN"
    ) == _error(ds)


def test_all_nan_channel_is_refused(ds: Path) -> None:
    """A channel that is NaN in every row of its stream is refused, naming file and column."""
    force = pd.read_parquet(ds / "streams/force.parquet")
    force["fy"] = float("nan")
    _rewrite(ds, "streams/force.parquet", force)
    assert (
        f"{ds}/streams/force.parquet: column 'fy' has no finite value in its "
        f"{len(force)} rows (all NaN or infinite); a channel must hold data"
    ) == _error(ds)


def test_dataset_with_zero_trials_is_refused(ds: Path) -> None:
    """A dataset folder whose trials.parquet has no rows (and empty streams) is refused."""
    for rel in ("trials.parquet", "streams/force.parquet", "streams/events.parquet"):
        _rewrite(ds, rel, pd.read_parquet(ds / rel).iloc[:0])
    manifest = _manifest(ds)
    del manifest["n_trials"]
    _write_manifest(ds, manifest)
    assert (
        f"{ds}/trials.parquet: has no rows; a dataset holds at least one trial"
    ) == _error(ds)


# -- the declared schema -----------------------------------------------------------------


def test_schema_is_valid_draft_2020_12_and_matches_the_reader() -> None:
    """The shipped schema is a valid draft 2020-12 document for this SCHEMA_VERSION."""
    schema = json.loads(SCHEMA_FILE.read_text())
    jsonschema.Draft202012Validator.check_schema(schema)
    assert (
        "https://json-schema.org/draft/2020-12/schema",
        SCHEMA_VERSION,
        schema,
    ) == (
        schema["$schema"],
        schema["properties"]["schema_version"]["const"],
        manifest_schema(),
    )


def test_schema_accepts_every_manifest_slipkit_writes(pristine: Path) -> None:
    """The manifest save_dataset writes is valid under the plain draft 2020-12 validator."""
    errors = list(
        jsonschema.Draft202012Validator(manifest_schema()).iter_errors(
            _manifest(pristine)
        )
    )
    assert [] == errors


def test_docs_print_the_shipped_schema() -> None:
    """docs/dataset-format.md prints the schema file verbatim (one JSON block)."""
    doc = (ROOT / "docs/dataset-format.md").read_text()
    block = doc.split("<!-- schema:begin -->")[1].split("<!-- schema:end -->")[0]
    text = block.strip().removeprefix("```json").removesuffix("```").strip()
    assert json.loads(SCHEMA_FILE.read_text()) == json.loads(text)


def test_wheel_ships_the_schema(tmp_path: Path) -> None:
    """A built wheel carries slipkit/data/schema/dataset-manifest.schema.json."""
    import zipfile

    from tests.wheel import build_wheel

    wheel = build_wheel(tmp_path)
    names = set(zipfile.ZipFile(wheel).namelist())
    assert "slipkit/data/schema/dataset-manifest.schema.json" in names


# -- Hypothesis: any field-by-field mutation is a clean error or a valid load ------------


def _paths(node: Any, prefix: tuple[Any, ...] = ()) -> list[tuple[Any, ...]]:
    """Every path to a value in a JSON tree (object keys and list indices)."""
    out = [prefix] if prefix else []
    if isinstance(node, dict):
        for key, value in node.items():
            out.extend(_paths(value, (*prefix, key)))
    elif isinstance(node, list):
        for i, value in enumerate(node):
            out.extend(_paths(value, (*prefix, i)))
    return out


JUNK = st.recursive(
    st.none()
    | st.booleans()
    | st.integers(-(10**30), 10**30)
    | st.floats(allow_nan=True, allow_infinity=True)
    | st.sampled_from(["", " ", "..", "/", "/etc/passwd", "../../x", "trial_id", "t"])
    | st.text(max_size=8),
    lambda inner: (
        st.lists(inner, max_size=3)
        | st.dictionaries(st.text(max_size=5), inner, max_size=3)
    ),
    max_leaves=6,
)
NUMBERS = st.sampled_from(
    [0, -1, -3, 1, 10**18, 10**400, 1e308, -1e308, 1e-300, math.nan, math.inf, 0.5]
)


@settings(
    max_examples=200,
    deadline=None,
    suppress_health_check=[HealthCheck.function_scoped_fixture],
)
@given(data=st.data())
def test_mutated_manifest_is_a_clean_error_or_a_valid_load(
    pristine: Path, ds: Path, data: st.DataObject
) -> None:
    """Dropping or renaming a field, or replacing one by another JSON type, a huge/negative/
    NaN number, an empty string or nested junk, ends in one SlipkitError line or a load."""
    manifest = _manifest(pristine)
    path = data.draw(st.sampled_from(_paths(manifest)), label="path")
    parent = manifest
    for key in path[:-1]:
        parent = parent[key]
    actions = ["drop", "junk", "number", "empty"]
    if isinstance(parent, dict):
        actions.append("rename")
    action = data.draw(st.sampled_from(actions), label="action")
    key = path[-1]
    if action == "drop":
        del parent[key]
    elif action == "junk":
        parent[key] = data.draw(JUNK, label="junk")
    elif action == "number":
        parent[key] = data.draw(NUMBERS, label="number")
    elif action == "empty":
        parent[key] = ""
    else:
        parent[data.draw(st.text(max_size=8), label="new key")] = parent.pop(key)
    _write_manifest(ds, manifest)
    try:
        load_dataset(ds)
    except SlipkitError as exc:
        message = str(exc)
    else:
        return  # a harmless mutation (a description, a provenance value): it loads
    assert (1, True) == (len(message.splitlines()), message.startswith(str(ds)))


# -- the CLI reaches the same one-line errors ----------------------------------------------


@pytest.mark.parametrize(
    ("damage", "message"),
    [
        pytest.param(
            lambda ds: _edit(ds, _set("streams", "force", "rate_hz", value=True)),
            f"streams.force.rate_hz: expected {RATE}, got true",
            id="rate_hz-true",
        ),
        pytest.param(
            lambda ds: _edit(ds, _set("groups", value=[{}])),
            f"groups[0]: expected {COLUMN}, got an object",
            id="groups-object",
        ),
        pytest.param(
            lambda ds: (ds / "manifest.json").write_text("[" * 100_000 + "]" * 100_000),
            f"nests JSON deeper than Python can parse; at most {MAX_DEPTH} levels",
            id="deep-nesting",
        ),
    ],
)
def test_slipkit_info_prints_the_same_one_line_error(
    ds: Path,
    capsys: pytest.CaptureFixture[str],
    damage: Callable[[Path], None],
    message: str,
) -> None:
    """`slipkit info dataset=<bad>` exits 2 with one line: slipkit info: error: <file>: <field>..."""
    damage(ds)
    with pytest.raises(SystemExit) as exc:
        main(["info", f"dataset={ds}"])
    err = capsys.readouterr().err
    assert (2, [f"slipkit info: error: {ds}/manifest.json: {message}"]) == (
        exc.value.code,
        err.strip().splitlines(),
    )


# -- the generic CSV importer ---------------------------------------------------------------


def _csv(path: Path, text: str) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text, encoding="utf-8")
    return path


HINT = (
    "; without channels=[...], every column that is not the time, trial, label or "
    "group column is a channel: give text columns as label_columns or "
    "group_columns, or list channels=[...]"
)


@pytest.mark.parametrize(
    ("cell", "shown"),
    [("abc", "'abc'"), ('"1,5"', "'1,5'"), ("0x10", "'0x10'"), ("True", "'True'")],
    ids=["abc", "1,5", "0x10", "True"],
)
def test_one_non_numeric_cell_is_named_not_dropped(
    tmp_path: Path, cell: str, shown: str
) -> None:
    """Without channels=, one bad cell in a channel names file, line and column (the
    channel used to vanish silently)."""
    file = _csv(tmp_path / "r.csv", f"fx,fz\n1,2\n3,{cell}\n5,6\n")
    with pytest.raises(SourceFormatError) as info:
        read_csv_dataset(file, sensor="x", rate_hz=10.0)
    assert f"{file}: line 3, column 'fz': {shown} is not a number{HINT}" == str(
        info.value
    )


@pytest.mark.parametrize(
    "channels", [None, ["fx", "fz"]], ids=["default-channels", "given-channels"]
)
def test_true_false_column_is_not_read_as_one_and_zero(
    tmp_path: Path, channels: list[str] | None
) -> None:
    """A column of True/False is refused naming line and column, with or without channels=."""
    file = _csv(tmp_path / "r.csv", "fx,fz\n1,True\n3,False\n")
    with pytest.raises(SourceFormatError) as info:
        read_csv_dataset(file, sensor="x", rate_hz=10.0, channels=channels)
    hint = HINT if channels is None else ""
    assert f"{file}: line 2, column 'fz': True is not a number (write 1/0){hint}" == (
        str(info.value)
    )


@pytest.mark.parametrize(
    ("header", "message"),
    [
        (
            "fx,fx,fz",
            "line 1, column 2: column name 'fx' repeats column 1; column names must "
            "be unique",
        ),
        (
            "fx,,fz",
            "line 1, column 2: empty column name; every column of the header needs a "
            "name",
        ),
    ],
    ids=["repeated", "empty"],
)
def test_duplicate_or_empty_column_names_are_refused(
    tmp_path: Path, header: str, message: str
) -> None:
    """A repeated or empty header name is refused (pandas renames them fx.1 / Unnamed: 1)."""
    file = _csv(tmp_path / "r.csv", f"{header}\n1,2,3\n4,5,6\n")
    with pytest.raises(SourceFormatError) as info:
        read_csv_dataset(file, sensor="x", rate_hz=10.0)
    assert f"{file}: {message}" == str(info.value)


def test_header_shorter_than_every_row_is_refused(tmp_path: Path) -> None:
    """Rows one field longer than the header are refused (pandas would make the first
    field an index and shift every column)."""
    file = _csv(tmp_path / "r.csv", "fx,fz\n1,2,3\n4,5,6\n")
    with pytest.raises(SourceFormatError) as info:
        read_csv_dataset(file, sensor="x", rate_hz=10.0)
    assert (
        f"{file}: line 2 has 3 fields but the header (line 1) has 2; every row needs "
        "as many fields as the header"
    ) == str(info.value)


@pytest.mark.parametrize(
    ("column", "use"),
    [
        ("t", "time_column='t' if it holds times in s"),
        ("trial_id", "trial_column='trial_id' if it names the trials"),
    ],
    ids=["t", "trial_id"],
)
def test_column_named_like_slipkits_own_is_a_clear_error(
    tmp_path: Path, column: str, use: str
) -> None:
    """A CSV column 't' or 'trial_id' that would become a channel is refused by name."""
    file = _csv(tmp_path / "r.csv", f"{column},fx\n0,1\n1,2\n")
    what = {"t": "time (s)", "trial_id": "trial id"}[column]
    with pytest.raises(SourceFormatError) as info:
        read_csv_dataset(file, sensor="x", rate_hz=10.0)
    assert (
        f"{file}: column {column!r} would be a channel named like slipkit's own "
        f"{what} column; give {use}, or leave it out of channels=[...] (or rename it)"
    ) == str(info.value)


@pytest.mark.parametrize("role", ["label_columns", "group_columns"])
def test_label_or_group_named_trial_id_is_refused(tmp_path: Path, role: str) -> None:
    """label_columns / group_columns naming 'trial_id' is refused, not merged into the ids."""
    file = _csv(tmp_path / "r.csv", "trial_id,fx\nA,1\nA,2\n")
    with pytest.raises(SourceFormatError) as info:
        read_csv_dataset(file, sensor="x", rate_hz=10.0, **{role: ["trial_id"]})
    assert (
        f"{role} names 'trial_id', which is slipkit's own trial id column in every "
        "dataset; rename the column"
    ) == str(info.value)


def test_time_column_named_t_is_still_accepted(tmp_path: Path) -> None:
    """A column 't' given as time_column is read as the time (no collision)."""
    file = _csv(tmp_path / "r.csv", "t,fx\n0.0,1\n0.5,2\n")
    ds = read_csv_dataset(file, sensor="x", time_column="t")
    assert ([0.0, 0.5], ("fx",)) == (
        ds.stream("signal")["t"].tolist(),
        ds.streams["signal"].channels,
    )


def test_a_channel_that_is_also_a_label_is_refused(tmp_path: Path) -> None:
    """channels= listing a label column is refused: each column has one role."""
    file = _csv(tmp_path / "r.csv", "onset,fx\n0.5,1\n0.5,2\n")
    with pytest.raises(SourceFormatError) as info:
        read_csv_dataset(
            file,
            sensor="x",
            rate_hz=10.0,
            channels=["fx", "onset"],
            label_columns=["onset"],
        )
    assert (
        "channels: column 'onset' is given both as channels and as label_columns; "
        "each column has one role"
    ) == str(info.value)


def test_saved_csv_import_with_text_label_round_trips(tmp_path: Path) -> None:
    """A valid CSV with text labels and groups still imports, saves and loads unchanged."""
    file = _csv(
        tmp_path / "r.csv",
        "run,obj,kind,fx\n1,cube,slip,0.5\n1,cube,slip,0.7\n2,ball,hold,1.5\n",
    )
    ds = read_csv_dataset(
        file,
        sensor="x",
        rate_hz=100.0,
        trial_column="run",
        label_columns=["kind"],
        group_columns=["obj"],
    )
    loaded = load_dataset(save_dataset(ds, tmp_path / "out"))
    assert (ds.fingerprint(), ["1", "2"]) == (loaded.fingerprint(), loaded.trial_ids)
