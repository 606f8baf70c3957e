"""Bundle format: writing, loading, and refusing tampered or malformed bundles."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st
from tests.runtime.helpers import LinearCase, linear_graph, manifest

from slipkit.errors import SlipkitError
from slipkit.runtime import (
    FORMAT,
    SCHEMA_VERSION,
    BundleError,
    FrameError,
    load_bundle,
    validate_manifest,
    write_bundle,
)


@pytest.fixture
def case(tmp_path: Path) -> LinearCase:
    return LinearCase(tmp_path)


def test_round_trip_keeps_every_field(case: LinearCase) -> None:
    """A written bundle loads back with the frame spec, rule, budget and file hashes it was given."""
    bundle = load_bundle(case.path)
    m = bundle.manifest
    assert (FORMAT, SCHEMA_VERSION) == (m.raw["format"], m.raw["schema_version"])
    assert (4, 1, 100.0, (3,)) == (
        m.frame.window,
        m.frame.hop,
        m.frame.rate_hz,
        m.frame.shape,
    )
    assert case.threshold == m.decision.threshold
    assert ("threshold", "slip", 2) == (
        m.decision.rule,
        m.decision.positive,
        m.debounce_k,
    )
    assert (10.0, 1.0) == (m.budget.frame_period_ms, m.budget.p99_ms)
    assert {"model.onnx", "replay.npz"} == set(m.files)
    assert case.path / "replay.npz" == bundle.replay_path
    assert "abc123" == m.training["data_fingerprint"]


def test_tampered_model_is_refused_naming_the_file(case: LinearCase) -> None:
    """A model.onnx changed after export is refused before onnxruntime sees it, naming the file."""
    model = case.path / "model.onnx"
    model.write_bytes(linear_graph(np.ones(12), 0.0))
    with pytest.raises(
        BundleError, match=r"model\.onnx: sha256 .* field 'files\.model\.onnx'"
    ) as info:
        load_bundle(case.path)
    assert str(model) == info.value.file


def test_tampered_replay_is_refused(case: LinearCase) -> None:
    """A listed replay.npz whose bytes changed is refused, naming it."""
    (case.path / "replay.npz").write_bytes(b"not the recording")
    with pytest.raises(BundleError, match=r"replay\.npz: sha256"):
        load_bundle(case.path)


def _drop(path: str) -> Any:
    *parents, last = path.split(".")

    def fn(man: dict[str, Any]) -> None:
        obj = man
        for p in parents:
            obj = obj[p]
        del obj[last]

    return fn


@pytest.mark.parametrize(
    "field",
    [
        "format",
        "schema_version",
        "name",
        "frame",
        "frame.rate_hz",
        "frame.window",
        "frame.channels",
        "inputs",
        "outputs",
        "decision",
        "decision.rule",
        "threshold",
        "debounce",
        "debounce.k",
        "budget_ms",
        "budget_ms.p99",
        "opset",
        "producer",
        "files",
    ],
)
def test_missing_field_is_named(case: LinearCase, field: str) -> None:
    """Each required manifest field, when absent, is refused with its dotted name."""
    case.edit_manifest(_drop(field))
    with pytest.raises(BundleError) as info:
        load_bundle(case.path)
    assert str(case.path / "manifest.json") == info.value.file
    assert field == info.value.field


def _set(path: str, value: Any) -> Any:
    *parents, last = path.split(".")

    def fn(man: dict[str, Any]) -> None:
        obj: Any = man
        for p in parents:
            obj = obj[int(p)] if p.isdigit() else obj[p]
        obj[int(last) if last.isdigit() else last] = value

    return fn


@pytest.mark.parametrize(
    ("path", "value", "field"),
    [
        ("format", "onnx-zip", "format"),
        ("schema_version", 4, "schema_version"),
        ("schema_version", 1, "schema_version"),
        ("schema_version", "1", "schema_version"),
        ("frame.window", 0, "frame.window"),
        ("frame.hop", 1.5, "frame.hop"),
        ("frame.rate_hz", "fast", "frame.rate_hz"),
        ("frame.rate_hz", -100.0, "frame.rate_hz"),
        ("frame.channels", ["a", "b"], "frame.channels"),
        ("frame.channels", ["a", "a", "b"], "frame.channels"),
        ("threshold", math.nan, "threshold"),
        ("threshold", "0.5", "threshold"),
        ("debounce.k", True, "debounce.k"),
        ("debounce.k", 0, "debounce.k"),
        ("budget_ms.p99", 11.0, "budget_ms.p99"),
        ("decision.rule", "max", "decision.rule"),
        ("decision.output", "logits", "decision.output"),
        ("decision.positive", "slipping", "decision.positive"),
        ("decision.column", 1, "decision.column"),
        ("inputs.0.name", "features", "inputs[0].name"),
        ("inputs.0.shape", [1, 13], "inputs[0].shape"),
        ("inputs.0.dtype", "int64", "inputs[0].dtype"),
        ("outputs.0.name", "proba", "decision.output"),
        ("outputs", [{"name": "score"}, {"name": "proba"}], "outputs[1].name"),
        ("preprocessing.0.op", "eval", "preprocessing[0].op"),
        ("preprocessing.0.scale", [1.0, 0.0, 1.0], "preprocessing[0].scale"),
        ("preprocessing.0.mean", [1.0, 2.0], "preprocessing[0].mean"),
        ("preprocessing.0.code", "import os", "preprocessing[0].code"),
        ("session.graph_optimization_level", "max", "session.graph_optimization_level"),
        ("session.warmup", -1, "session.warmup"),
        ("training", [], "training"),
        ("producer.onnx", 1.23, "producer.onnx"),
        ("files.model.onnx", "deadbeef", "files.model.onnx"),
        ("pickle", "yes", "pickle"),
    ],
)
def test_invalid_field_is_named(
    case: LinearCase, path: str, value: Any, field: str
) -> None:
    """A field of the wrong type or range (or an unknown one) is refused with its dotted name."""
    if path == "files.model.onnx":
        case.edit_manifest(lambda m: m["files"].__setitem__("model.onnx", value))
    else:
        case.edit_manifest(_set(path, value))
    with pytest.raises(BundleError) as info:
        load_bundle(case.path)
    assert field == info.value.field


def test_not_json_is_refused(case: LinearCase) -> None:
    """A manifest that is not JSON is refused naming manifest.json."""
    (case.path / "manifest.json").write_text("{format: slipkit")
    with pytest.raises(BundleError, match=r"manifest\.json: is not valid JSON"):
        load_bundle(case.path)


def test_missing_folder_and_files(tmp_path: Path, case: LinearCase) -> None:
    """A missing folder, manifest or listed file is refused naming the path."""
    with pytest.raises(BundleError, match="not a bundle folder"):
        load_bundle(tmp_path / "nope")
    (case.path / "replay.npz").unlink()
    with pytest.raises(BundleError, match=r"replay\.npz: is missing"):
        load_bundle(case.path)
    (case.path / "manifest.json").unlink()
    with pytest.raises(BundleError, match=r"manifest\.json: is missing"):
        load_bundle(case.path)


def test_bundle_error_is_a_slipkit_error() -> None:
    """BundleError is a SlipkitError (the slipkit CLI prints it without a traceback)."""
    assert issubclass(BundleError, SlipkitError)


def test_failed_write_leaves_nothing(tmp_path: Path) -> None:
    """write_bundle with a manifest that does not match the graph leaves no folder behind."""
    man = manifest(13, threshold=0.0)  # the graph below takes 12 values
    with pytest.raises(BundleError, match=r"inputs\[0\]\.shape"):
        write_bundle(tmp_path / "b", linear_graph(np.ones(12), 0.0), man)
    assert [] == list(tmp_path.iterdir())


def test_write_refuses_existing_folder_unless_overwrite(case: LinearCase) -> None:
    """An existing bundle is replaced only with overwrite=True."""
    man = manifest(12, threshold=1.5, window=4)
    with pytest.raises(BundleError, match="already exists"):
        write_bundle(case.path, linear_graph(np.ones(12), 0.0), man)
    write_bundle(case.path, linear_graph(np.ones(12), 0.0), man, overwrite=True)
    assert 1.5 == load_bundle(case.path).manifest.decision.threshold
    assert ["linear"] == [p.name for p in case.path.parent.iterdir()]


def test_dynamic_batch_dimension_is_accepted(tmp_path: Path) -> None:
    """A graph with a symbolic batch dimension loads with the manifest's concrete shape."""
    write_bundle(
        tmp_path / "b", linear_graph(np.ones(12), 0.0, batch="N"), manifest(12)
    )
    assert (1, 12) == load_bundle(tmp_path / "b").manifest.inputs[0].shape


def test_manifest_is_plain_json(case: LinearCase) -> None:
    """numpy parameters given to write_bundle are stored as JSON lists, nothing else."""
    man = json.loads((case.path / "manifest.json").read_text())
    assert case.mean.tolist() == man["preprocessing"][0]["mean"]


json_values = st.recursive(
    st.none() | st.booleans() | st.integers() | st.floats() | st.text(max_size=5),
    lambda inner: (
        st.lists(inner, max_size=3)
        | st.dictionaries(st.text(max_size=5), inner, max_size=3)
    ),
    max_leaves=6,
)


@settings(max_examples=60, deadline=None)
@given(
    field=st.sampled_from(["rate_hz", "window", "hop", "shape", "channels"]),
    value=json_values,
)
@example(
    field="shape", value=[993, 1056]
)  # too large for the window: named as the shape
def test_any_json_value_is_accepted_or_named(field: str, value: Any) -> None:
    """Whatever JSON sits in a frame field, validation accepts it or names that field."""
    man = manifest(12)
    man.update(
        format=FORMAT, schema_version=SCHEMA_VERSION, files={"model.onnx": "0" * 64}
    )
    man["frame"][field] = value
    fields = []
    try:
        validate_manifest(man)
    except BundleError as exc:
        fields.append(exc.field)
    # A well-typed shape that disagrees with the channel count is named at the
    # cross-field check on frame.channels (whose message quotes frame.shape).
    named = [f"frame.{field}"] + (["frame.channels"] if field == "shape" else [])
    assert fields in ([], *([n] for n in named))


def test_write_refuses_replay_of_the_wrong_shape(tmp_path: Path) -> None:
    """Replay frames that do not match frame.shape are refused before anything is written."""
    with pytest.raises(FrameError, match=r"frames of shape \[5\]"):
        write_bundle(
            tmp_path / "b",
            linear_graph(np.ones(12), 0.0),
            manifest(12),
            replay=(np.zeros((10, 5)), np.arange(10.0)),
        )
    assert [] == list(tmp_path.iterdir())


def _argmax(m: dict[str, Any], **extra: Any) -> None:
    """Turn the linear case's manifest into a (schema 3) argmax one over two classes."""
    m.pop("threshold", None)
    m["decision"] = {
        "output": "score",
        "rule": "argmax",
        "classes": ["slip", "static"],
        "positive": "slip",
        **extra,
    }


@pytest.mark.parametrize(
    ("edit", "field", "problem"),
    [
        (
            lambda m: _argmax(m, slip_classes=["slip", "x"]),
            "decision.slip_classes",
            "does not list",
        ),
        (lambda m: _argmax(m, slip_classes=[]), "decision.slip_classes", "non-empty"),
        (
            lambda m: _argmax(m, slip_classes=["static"]),
            "decision.slip_classes",
            "positive",
        ),
        (
            lambda m: _argmax(m, slip_classes=["slip", "slip"]),
            "decision.slip_classes",
            "repeat",
        ),
        (
            lambda m: m["decision"].__setitem__("slip_classes", ["slip"]),
            "decision.slip_classes",
            "argmax rule only",
        ),
        (
            lambda m: m["budget_ms"].__setitem__("source", "guess"),
            "budget_ms.source",
            "one of",
        ),
        (
            lambda m: m["budget_ms"].update(
                source="data_rate_hz", frame_period=3.0, p99=0.3
            ),
            "budget_ms.frame_period",
            "gives 10 ms",
        ),
        (
            lambda m: m["training"].__setitem__("refit_on_all_data", "yes"),
            "training.refit_on_all_data",
            "true or false",
        ),
        (
            lambda m: m["training"].__setitem__("scored_on", "x" * 5000),
            "training.scored_on",
            "at most 4096",
        ),
        (
            lambda m: m["training"].__setitem__(
                "replay", {"trials": -1, "frames": 0, "held_out": True}
            ),
            "training.replay.trials",
            ">= 0",
        ),
        (
            lambda m: m["training"].__setitem__(
                "replay",
                {"trials": 1, "frames": 1, "held_out": True, "by_class": {"n": 1.5}},
            ),
            "training.replay.by_class.n",
            "integer",
        ),
        (
            lambda m: (
                m.__setitem__("schema_version", 2) or _argmax(m, slip_classes=["slip"])
            ),
            "decision.slip_classes",
            "not a known field",
        ),
    ],
)
def test_schema3_fields_are_checked_and_named(
    case: LinearCase, edit: Any, field: str, problem: str
) -> None:
    """slip_classes, budget_ms.source and the training provenance are bounded and named when wrong."""
    case.edit_manifest(lambda m: (m.setdefault("training", {}), edit(m)))
    with pytest.raises(BundleError) as info:
        load_bundle(case.path)
    assert (field, True) == (info.value.field, problem in str(info.value))


def test_schema2_bundle_still_loads(case: LinearCase) -> None:
    """A version-2 manifest (no schema-3 fields) loads with this runtime."""
    case.edit_manifest(lambda m: m.__setitem__("schema_version", 2))
    assert 2 == load_bundle(case.path).manifest.raw["schema_version"]


def test_budget_source_and_provenance_load(case: LinearCase) -> None:
    """A budget from the data's rate (100 Hz: 10 ms) and valid provenance load as written."""

    def edit(m: dict[str, Any]) -> None:
        m["budget_ms"] = {"frame_period": 10.0, "p99": 1.0, "source": "data_rate_hz"}
        m["training"] = {
            "refit_on_all_data": True,
            "held_out": False,
            "scored_on": "2-fold CV",
            "replay": {
                "trials": 3,
                "frames": 200,
                "held_out": False,
                "by_class": {"a": 3},
            },
        }

    case.edit_manifest(edit)
    m = load_bundle(case.path).manifest
    assert ("data_rate_hz", True) == (m.budget.source, m.training["refit_on_all_data"])


def test_edited_slip_classes_break_the_digest(tmp_path: Path) -> None:
    """Dropping a slip class from a signed manifest (not re-signed) is refused at manifest_sha256."""
    from tests.runtime.helpers import dos_like_bundle, edit_manifest

    bundle = dos_like_bundle(tmp_path)
    edit_manifest(
        bundle,
        lambda m: m["decision"].__setitem__("slip_classes", ["n"]),
        resign=False,
    )
    with pytest.raises(BundleError) as info:
        load_bundle(bundle)
    assert "manifest_sha256" == info.value.field


@pytest.mark.parametrize("opset", [16, 18])
def test_manifest_opset_other_than_the_graphs_is_refused_naming_both(
    case: LinearCase, opset: int
) -> None:
    """A re-signed manifest whose opset is not model.onnx's default-domain opset_import
    (17) is refused naming the field and both opsets."""
    case.edit_manifest(_set("opset", opset))
    with pytest.raises(BundleError) as info:
        load_bundle(case.path)
    assert "opset" == info.value.field
    assert f"is {opset} but model.onnx imports default-domain opset 17" in str(
        info.value
    )


def test_graph_opsets_are_read_as_onnx_reads_them() -> None:
    """onnx_opsets (a hand-written protobuf reader) gives onnx's own opset_import, the
    default domain as '' (also when spelled ai.onnx), the highest of a repeated one."""
    import onnx

    from slipkit.runtime.bundle import onnx_opsets

    model = onnx.load_from_string(linear_graph(np.ones(3), 0.0, opset=18))
    model.doc_string = "x" * 300  # a long length-delimited field before the opsets
    model.opset_import.extend(
        [
            onnx.helper.make_opsetid("ai.onnx.ml", 3),
            onnx.helper.make_opsetid("ai.onnx", 16),
        ]
    )
    assert {"": 18, "ai.onnx.ml": 3} == onnx_opsets(model.SerializeToString())
    with pytest.raises(ValueError, match="past the end"):
        onnx_opsets(model.SerializeToString()[:-3])


@pytest.mark.parametrize("dtype", ["<U8", "S8", "bool"])
def test_replay_timestamps_that_are_not_numbers_are_refused_naming_the_array(
    tmp_path: Path, dtype: str
) -> None:
    """Timestamps stored as strings (or booleans) are refused naming 'timestamps',
    not converted."""
    from slipkit.runtime.sources import load_replay

    path = tmp_path / "r.npz"
    np.savez(
        path,
        frames=np.zeros((3, 3)),
        timestamps=np.array([0.0, 0.01, 0.02]).astype(dtype),
    )
    with pytest.raises(FrameError, match=r"'timestamps' must be numbers \(s\); got"):
        load_replay(path, (3,), 100.0)


def _resigned_threshold(case: LinearCase) -> None:
    """Set the threshold to -1e9 and recompute manifest_sha256, as anyone can."""
    case.edit_manifest(_set("threshold", -1e9))


def test_signed_bundle_refuses_an_edit_with_a_recomputed_digest(
    tmp_path: Path,
) -> None:
    """A bundle written with a key loads with it; after an edit that recomputes
    manifest_sha256 it still loads without the key (the digest is a checksum) and is
    refused with it, naming manifest.hmac."""
    key = b"lab secret \x00\xff"
    c = LinearCase(tmp_path)
    man = json.loads((c.path / "manifest.json").read_text())
    for k in ("files", "manifest_sha256"):
        man.pop(k)
    signed = write_bundle(
        tmp_path / "signed", (c.path / "model.onnx").read_bytes(), man, key=key
    )
    assert c.threshold == load_bundle(signed, key=key).manifest.decision.threshold
    c.path = signed
    _resigned_threshold(c)
    assert -1e9 == load_bundle(signed).manifest.decision.threshold
    with pytest.raises(
        BundleError, match=r"does not match manifest\.json under the given key"
    ) as info:
        load_bundle(signed, key=key)
    assert str(signed / "manifest.hmac") == info.value.file


def test_a_key_refuses_an_unsigned_bundle_and_a_signature_under_another_key(
    case: LinearCase, tmp_path: Path
) -> None:
    """With a key: no manifest.hmac is refused as unsigned; one made with another
    key is refused as not matching."""
    from slipkit.runtime.bundle import manifest_hmac

    with pytest.raises(BundleError, match="is missing: the bundle is not signed"):
        load_bundle(case.path, key=b"k")
    data = (case.path / "manifest.json").read_bytes()
    (case.path / "manifest.hmac").write_text(manifest_hmac(data, b"other"))
    with pytest.raises(BundleError, match="does not match"):
        load_bundle(case.path, key=b"k")
    assert (
        case.threshold
        == load_bundle(case.path, key=b"other").manifest.decision.threshold
    )


@pytest.mark.parametrize("kind", ["empty", "inside", "missing"])
def test_key_file_rules_are_named(case: LinearCase, tmp_path: Path, kind: str) -> None:
    """A key file that is empty, inside the bundle or absent: OptionError naming the option."""
    from slipkit.runtime import read_key
    from slipkit.runtime.errors import OptionError

    path = {
        "empty": tmp_path / "empty.key",
        "inside": case.path / "lab.key",
        "missing": tmp_path / "none.key",
    }[kind]
    if kind != "missing":
        path.write_bytes(b"" if kind == "empty" else b"secret")
    message = {
        "empty": "is empty",
        "inside": "is inside the bundle",
        "missing": "is not a file",
    }
    with pytest.raises(OptionError, match=f"--key: .*{message[kind]}"):
        read_key(path, "--key", bundles=(case.path,))
