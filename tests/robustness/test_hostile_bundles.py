"""Hostile bundles, replay files, datagrams and arguments against the gripper-PC runtime.

Issue 12, part C. Every test here failed before the fixes it documents
(``docs/robustness.md``, "Bundles and the runtime"): an edited manifest loaded, a
replaced graph with the same input loaded, a stray UDP index stopped a run for good,
and several inputs ended in a traceback or a hang. Sockets are loopback only and
every wait is bounded by a timeout.
"""

from __future__ import annotations

import json
import math
import shutil
import socket
import struct
import threading
import zipfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st
from onnx import TensorProto, helper, numpy_helper
from tests.runtime.helpers import LinearCase, edit_manifest, linear_graph

from slipkit._files import sha256_bytes
from slipkit.errors import SlipkitError
from slipkit.runtime import (
    BundleError,
    FrameError,
    ReplaySource,
    StreamLoop,
    UdpSender,
    UdpSource,
    load_bundle,
    load_replay,
)
from slipkit.runtime.bundle import DIGEST_FIELD, manifest_digest
from slipkit.runtime.cli import main, run

N_IN = 12  # LinearCase: window 4 x 3 channels


# -- bundles ---------------------------------------------------------------------------
@pytest.fixture(scope="module")
def base(tmp_path_factory: pytest.TempPathFactory) -> LinearCase:
    """One valid bundle (standardize + linear, window 4 of 3 channels, 200 replay frames)."""
    return LinearCase(tmp_path_factory.mktemp("hostile"), name="base")


@pytest.fixture
def bundle(base: LinearCase, tmp_path: Path) -> Path:
    """A fresh copy of the base bundle to break."""
    return Path(shutil.copytree(base.path, tmp_path / "bundle"))


def _graph(nodes: list[Any], outputs: list[Any], **extra: Any) -> bytes:
    """A one-input graph ``X`` (float32, [1, 12]) with the given nodes and outputs."""
    graph = helper.make_graph(
        nodes,
        "hostile",
        [helper.make_tensor_value_info("X", TensorProto.FLOAT, [1, N_IN])],
        outputs,
        initializer=extra.get("initializer", []),
    )
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])
    model.ir_version = 10
    return bytes(model.SerializeToString())


def _double_score() -> bytes:
    """The same input, but a float64 score."""
    w = numpy_helper.from_array(np.ones((N_IN, 1), np.float32), "W")
    return _graph(
        [
            helper.make_node("MatMul", ["X", "W"], ["xw"]),
            helper.make_node("Cast", ["xw"], ["score"], to=TensorProto.DOUBLE),
        ],
        [helper.make_tensor_value_info("score", TensorProto.DOUBLE, [1, 1])],
        initializer=[w],
    )


def _rank3_score() -> bytes:
    """The same input, but a score of shape [1, 1, 1]."""
    w = numpy_helper.from_array(np.ones((N_IN, 1), np.float32), "W")
    axes = numpy_helper.from_array(np.array([0], np.int64), "axes")
    return _graph(
        [
            helper.make_node("MatMul", ["X", "W"], ["xw"]),
            helper.make_node("Unsqueeze", ["xw", "axes"], ["score"]),
        ],
        [helper.make_tensor_value_info("score", TensorProto.FLOAT, [1, 1, 1])],
        initializer=[w, axes],
    )


def _failing_graph() -> bytes:
    """Loads, declares a [1, 1] score, but its first call fails (Reshape 12 -> 5 x 7)."""
    shape = numpy_helper.from_array(np.array([5, 7], np.int64), "s")
    return _graph(
        [helper.make_node("Reshape", ["X", "s"], ["score"])],
        [helper.make_tensor_value_info("score", TensorProto.FLOAT, [1, 1])],
        initializer=[shape],
    )


def _endless_graph(iterations: int = 10**12) -> bytes:
    """A Loop of ``iterations`` steps adding 1 to the input's sum: never ends in practice."""
    body = helper.make_graph(
        [
            helper.make_node("Identity", ["cond_in"], ["cond_out"]),
            helper.make_node("Add", ["acc_in", "one"], ["acc_out"]),
        ],
        "body",
        [
            helper.make_tensor_value_info("i", TensorProto.INT64, []),
            helper.make_tensor_value_info("cond_in", TensorProto.BOOL, []),
            helper.make_tensor_value_info("acc_in", TensorProto.FLOAT, [1, 1]),
        ],
        [
            helper.make_tensor_value_info("cond_out", TensorProto.BOOL, []),
            helper.make_tensor_value_info("acc_out", TensorProto.FLOAT, [1, 1]),
        ],
        initializer=[numpy_helper.from_array(np.ones((1, 1), np.float32), "one")],
    )
    return _graph(
        [
            helper.make_node("ReduceSum", ["X"], ["s"], keepdims=1),
            helper.make_node("Loop", ["M", "cond", "s"], ["score"], body=body),
        ],
        [helper.make_tensor_value_info("score", TensorProto.FLOAT, [1, 1])],
        initializer=[
            numpy_helper.from_array(np.array(iterations, np.int64), "M"),
            numpy_helper.from_array(np.array(True), "cond"),
        ],
    )


def _swap_graph(bundle: Path, model: bytes) -> None:
    """Replace model.onnx and re-sign both its checksum and the manifest digest."""
    (bundle / "model.onnx").write_bytes(model)
    edit_manifest(
        bundle, lambda m: m["files"].__setitem__("model.onnx", sha256_bytes(model))
    )


def _set(path: str, value: Any) -> Callable[[dict[str, Any]], None]:
    """An edit that sets the dotted ``path`` (list indices as numbers) to ``value``."""
    *parents, last = path.split(".")

    def fn(man: dict[str, Any]) -> None:
        obj: Any = man
        for p in parents:
            obj = obj[int(p)] if p.isdigit() else obj[p]
        obj[int(last) if last.isdigit() else last] = value

    return fn


# -- the manifest digest -----------------------------------------------------------------
def test_written_manifest_carries_its_own_digest(base: LinearCase) -> None:
    """write_bundle stores the sha256 of the canonical manifest in manifest_sha256."""
    man = json.loads((base.path / "manifest.json").read_text())
    assert manifest_digest(man) == man[DIGEST_FIELD]


@pytest.mark.parametrize(
    ("path", "value"),
    [
        ("threshold", -1e9),
        ("budget_ms.p99", 10.0),
        ("debounce.k", 1),
        ("frame.rate_hz", 50.0),
        ("session.warmup", 3),
        ("training.data_fingerprint", "forged"),
    ],
)
def test_edited_manifest_is_refused_by_its_digest(
    bundle: Path, path: str, value: Any
) -> None:
    """Any edited value (a threshold, a loosened budget, provenance) is refused naming manifest_sha256."""
    edit_manifest(bundle, _set(path, value), resign=False)
    with pytest.raises(BundleError) as info:
        load_bundle(bundle)
    assert (str(bundle / "manifest.json"), DIGEST_FIELD) == (
        info.value.file,
        info.value.field,
    )


def test_reformatted_manifest_still_loads(bundle: Path) -> None:
    """Whitespace and key order are not content: a re-indented manifest keeps its digest."""
    path = bundle / "manifest.json"
    man = json.loads(path.read_text())
    path.write_text(json.dumps(dict(reversed(list(man.items()))), indent=7))
    assert man["threshold"] == load_bundle(bundle).manifest.decision.threshold


def test_manifest_without_its_digest_is_refused(bundle: Path) -> None:
    """A manifest with the digest removed is refused naming manifest_sha256."""
    edit_manifest(bundle, lambda m: m.pop(DIGEST_FIELD), resign=False)
    with pytest.raises(BundleError, match="is missing") as info:
        load_bundle(bundle)
    assert DIGEST_FIELD == info.value.field


def test_loosened_budget_no_longer_passes_check(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """slipkit-run --check on a bundle whose budget was loosened by hand exits 2, not 0."""
    case = LinearCase(tmp_path, budget=(10.0, 1e-6), name="strict")
    loosen = _set("budget_ms", {"frame_period": 10_000.0, "p99": 10_000.0})
    edit_manifest(case.path, loosen, resign=False)
    with pytest.raises(SystemExit) as info:
        main([str(case.path), "--check"])
    assert 2 == info.value.code
    assert DIGEST_FIELD in capsys.readouterr().err


# -- bounded fields ------------------------------------------------------------------------
OUT_OF_RANGE = [
    ("frame.window", 10**9, "frame.window"),
    ("frame.hop", 10**12, "frame.hop"),
    ("frame.rate_hz", 1e300, "frame.rate_hz"),
    ("frame.shape", [10**6, 10**6], "frame.shape"),
    ("debounce.k", 10**12, "debounce.k"),
    ("budget_ms.frame_period", 1e12, "budget_ms.frame_period"),
    ("session.warmup", 10**12, "session.warmup"),
    ("session.intra_op_num_threads", 10**6, "session.intra_op_num_threads"),
    ("session.inter_op_num_threads", 10**6, "session.inter_op_num_threads"),
    ("opset", 10**9, "opset"),
    ("threshold", 10**400, "threshold"),
    ("training.metrics.test.f1", math.inf, "training.metrics.test.f1"),
]


@pytest.mark.parametrize(
    ("path", "value", "field"), OUT_OF_RANGE, ids=[c[0] for c in OUT_OF_RANGE]
)
def test_out_of_range_numbers_are_refused_by_field(
    bundle: Path, path: str, value: Any, field: str
) -> None:
    """Huge, endless or non-finite numbers in a (re-signed) manifest are refused naming the field."""
    edit_manifest(bundle, _set(path, value))
    with pytest.raises(BundleError) as info:
        load_bundle(bundle)
    assert field == info.value.field


@pytest.mark.parametrize(
    ("step", "field"),
    [
        ({"op": "baseline_first", "frames": 10**11}, "preprocessing[1].frames"),
        ({"op": "baseline_first", "frames": 1, "hop": 10**9}, "preprocessing[1].hop"),
    ],
    ids=["baseline-of-1e11-frames", "baseline-hop-1e9"],
)
def test_out_of_range_preprocessing_is_refused_by_field(
    bundle: Path, step: dict[str, Any], field: str
) -> None:
    """A baseline of 1e11 frames (or an endless select) is refused before anything is allocated."""
    edit_manifest(bundle, lambda m: m["preprocessing"].append(step))
    with pytest.raises(BundleError) as info:
        load_bundle(bundle)
    assert field == info.value.field


def test_deeply_nested_manifest_is_refused_in_one_message(bundle: Path) -> None:
    """JSON nested 100,000 levels deep (past Python's recursion limit) is a BundleError, not a RecursionError."""
    path = bundle / "manifest.json"
    text = path.read_text()
    deep = "[" * 100_000 + "]" * 100_000
    path.write_text(text.replace('"training": {', f'"junk": {deep}, "training": {{', 1))
    with pytest.raises(BundleError, match="nested") as info:
        load_bundle(bundle)
    assert str(path) == info.value.file


def test_moderately_nested_manifest_is_refused_naming_the_depth(bundle: Path) -> None:
    """A re-signed manifest nested 40 levels deep in a free-form field is refused naming the depth limit."""
    deep: Any = 0
    for _ in range(40):
        deep = [deep]
    edit_manifest(bundle, _set("training.junk", deep))
    with pytest.raises(BundleError, match="levels deep"):
        load_bundle(bundle)


def test_a_field_name_with_a_newline_stays_on_one_line(bundle: Path) -> None:
    """An unknown key holding CR / LF / NUL is named escaped, so the message stays one line (found by Hypothesis)."""
    edit_manifest(bundle, _set("frame.\r\nx\x00", None))
    with pytest.raises(BundleError) as info:
        load_bundle(bundle)
    assert ["frame.\r\nx\x00"] == [info.value.field]
    assert 1 == len(str(info.value).splitlines())
    assert "field 'frame.\\r\\nx\\x00'" in str(info.value)


# -- the graph against the manifest ------------------------------------------------------
@pytest.mark.parametrize(
    ("model", "field"),
    [
        (_double_score, "outputs[0].dtype"),
        (_rank3_score, "outputs[0].shape"),
        (lambda: linear_graph(np.ones((N_IN, 2)), 0.0), "outputs[0].shape"),
    ],
    ids=["float64-score", "rank-3-score", "two-column-score"],
)
def test_replaced_graph_with_the_same_input_is_refused(
    bundle: Path, model: Callable[[], bytes], field: str
) -> None:
    """A graph swapped for another with the same input but another score type or shape is refused naming the output field."""
    _swap_graph(bundle, model())
    with pytest.raises(BundleError) as info:
        load_bundle(bundle)
    assert field == info.value.field


def test_written_manifest_records_each_outputs_dtype_and_shape(
    base: LinearCase,
) -> None:
    """write_bundle fills in the score output's dtype and shape from the graph."""
    man = json.loads((base.path / "manifest.json").read_text())
    assert [{"name": "score", "dtype": "float32", "shape": [1, 1]}] == man["outputs"]


def test_onnxruntime_error_at_the_first_call_names_the_model(bundle: Path) -> None:
    """A graph that loads but fails on its first call is a BundleError naming model.onnx, not onnxruntime's Fail."""
    _swap_graph(bundle, _failing_graph())
    with pytest.raises(BundleError, match=r"onnxruntime refused it: .*Reshape") as info:
        load_bundle(bundle)
    assert str(bundle / "model.onnx") == info.value.file


def test_never_ending_graph_is_stopped_by_the_load_deadline(bundle: Path) -> None:
    """A Loop of 1e12 iterations is stopped at the load deadline and refused naming model.onnx."""
    _swap_graph(bundle, _endless_graph())
    with pytest.raises(BundleError, match="load deadline") as info:
        load_bundle(bundle, deadline_s=0.2)
    assert str(bundle / "model.onnx") == info.value.file


def test_a_short_loop_passes_the_deadline(bundle: Path) -> None:
    """The same Loop graph with 3 iterations loads: the deadline stops only what does not end."""
    _swap_graph(bundle, _endless_graph(3))
    assert 3.0 == float(
        np.asarray(
            load_bundle(bundle, deadline_s=5.0).session.run(
                None, {"X": np.zeros((1, N_IN), np.float32)}
            )[0]
        ).item()
    )


def _value_dependent_graph() -> bytes:
    """Gathers entry ``int(sum(X))`` of a 2-entry table: fine on zeros, fails on large frames."""
    table = numpy_helper.from_array(np.array([[0.5], [1.5]], np.float32), "T")
    return _graph(
        [
            helper.make_node("ReduceSum", ["X"], ["s"], keepdims=0),
            helper.make_node("Cast", ["s"], ["i"], to=TensorProto.INT64),
            helper.make_node("Gather", ["T", "i"], ["g"], axis=0),
            helper.make_node("Reshape", ["g", "shape"], ["score"]),
        ],
        [helper.make_tensor_value_info("score", TensorProto.FLOAT, [1, 1])],
        initializer=[
            table,
            numpy_helper.from_array(np.array([1, 1], np.int64), "shape"),
        ],
    )


def test_onnxruntime_error_on_a_later_frame_names_the_model_and_frame(
    bundle: Path,
) -> None:
    """A graph that fails only on some frames stops the loop with a BundleError naming model.onnx and the frame."""
    _swap_graph(bundle, _value_dependent_graph())
    loaded = load_bundle(bundle)
    frames = np.zeros((10, 3), np.float32)
    frames[6:] = 1e6  # standardised, the window sum is far past the table
    source = ReplaySource(frames, np.arange(10) / 100.0)
    with pytest.raises(
        BundleError, match=r"onnxruntime failed on stream frame 6: "
    ) as info:
        StreamLoop(loaded).run(source)
    assert str(bundle / "model.onnx") == info.value.file


# -- replay files ------------------------------------------------------------------------
def _npy_header(shape: tuple[int, ...], dtype: str = "<f8") -> bytes:
    """A version-1.0 .npy header for ``shape`` (no data follows)."""
    text = f"{{'descr': '{dtype}', 'fortran_order': False, 'shape': {shape}, }}"
    pad = 64 - (10 + len(text) + 1) % 64
    text += " " * pad + "\n"
    return b"\x93NUMPY\x01\x00" + struct.pack("<H", len(text)) + text.encode()


def test_npy_header_claiming_1e11_rows_is_refused_before_allocating(
    tmp_path: Path,
) -> None:
    """A 1 kB .npy whose header claims 1e11 frames is refused naming the file, with no allocation."""
    path = tmp_path / "huge.npy"
    path.write_bytes(_npy_header((10**11, 3)) + b"\0" * 960)
    with pytest.raises(FrameError, match="header claims shape") as info:
        load_replay(path, (3,), 100.0)
    assert str(path) == info.value.where


def test_real_zip_bomb_is_refused_by_its_member_size(tmp_path: Path) -> None:
    """An .npz member that unpacks to 16 MiB is refused from its zip entry when the cap is 1 MiB."""
    path = tmp_path / "bomb.npz"
    n = (16 << 20) // 24
    with (
        zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as zf,
        zf.open("frames.npy", "w") as fh,
    ):
        fh.write(_npy_header((n, 3)))
        fh.write(bytes(n * 24))
    assert path.stat().st_size < 1 << 20  # it is a bomb: small on disk
    with pytest.raises(FrameError, match=r"frames\.npy' unpacks to"):
        load_replay(path, (3,), 100.0, max_bytes=1 << 20)


def _claimed_bomb(path: Path) -> None:
    """A small .npz whose zip entry claims frames.npy unpacks to ~4 GiB."""
    frames = np.zeros((10, 3))
    np.savez_compressed(path, frames=frames, timestamps=np.arange(10.0))
    data = bytearray(path.read_bytes())
    # Central directory entry of frames.npy: uncompressed size at offset 24.
    at = data.index(b"PK\x01\x02")
    data[at + 24 : at + 28] = struct.pack("<I", 0xFFFFFFF0)
    path.write_bytes(bytes(data))


# -- slipkit-run: one line, exit 2, never a traceback -------------------------------------
def _truncated_npz(path: Path, base: LinearCase) -> None:
    np.savez(path, frames=base.frames, timestamps=base.timestamps)
    path.write_bytes(path.read_bytes()[:700])


def _cases(tmp: Path, base: LinearCase) -> dict[str, tuple[list[str], str]]:
    """name -> (slipkit-run arguments, text the one-line error must contain)."""
    b = str(base.path)
    garbage = tmp / "garbage.npz"
    garbage.write_bytes(b"PK\x03\x04" + bytes(range(256)) * 8)
    noise = tmp / "noise.npz"
    noise.write_bytes(bytes(range(256)) * 4)
    trunc = tmp / "truncated.npz"
    _truncated_npz(trunc, base)
    huge = tmp / "huge.npy"
    huge.write_bytes(_npy_header((10**11, 3)) + b"\0" * 960)
    bomb = tmp / "bomb.npz"
    _claimed_bomb(bomb)
    scalar = tmp / "scalar.npy"
    np.save(scalar, np.float64(3.0))

    def broken(name: str, edit: Callable[[Path], None]) -> str:
        path = Path(shutil.copytree(base.path, tmp / name))
        edit(path)
        return str(path)

    def manifest_edit(path: str, value: Any) -> Callable[[Path], None]:
        return lambda p: edit_manifest(p, _set(path, value))

    def deep(p: Path) -> None:
        text = (p / "manifest.json").read_text()
        nested = "[" * 50_000 + "]" * 50_000
        (p / "manifest.json").write_text(text.replace("{", '{"x": ' + nested + ",", 1))

    def not_utf8(p: Path) -> None:
        (p / "manifest.json").write_bytes(b"\xff\xfe{}")

    json_dir = tmp / "json-dir"
    (json_dir / "x").mkdir(parents=True)
    return {
        "truncated npz": (
            [b, "--replay", str(trunc)],
            "truncated.npz: not a numpy",
        ),
        "garbage npz": ([b, "--replay", str(garbage)], "garbage.npz: not a numpy"),
        "noise": ([b, "--replay", str(noise)], "noise.npz: not a numpy"),
        "1e11-row npy": ([b, "--replay", str(huge)], "huge.npy: not a numpy"),
        "zip bomb": ([b, "--replay", str(bomb)], "zip bomb"),
        "scalar npy": ([b, "--replay", str(scalar)], "scalar.npy: 'frames'"),
        "huge window": (
            [broken("window", manifest_edit("frame.window", 10**9))],
            "field 'frame.window'",
        ),
        "huge baseline": (
            [
                broken(
                    "baseline",
                    lambda p: edit_manifest(
                        p,
                        lambda m: m["preprocessing"].append(
                            {"op": "baseline_first", "frames": 10**11}
                        ),
                    ),
                )
            ],
            "field 'preprocessing[1].frames'",
        ),
        "million threads": (
            [broken("threads", manifest_edit("session.intra_op_num_threads", 10**6))],
            "field 'session.intra_op_num_threads'",
        ),
        "endless warm-up": (
            [broken("warmup", manifest_edit("session.warmup", 10**12))],
            "field 'session.warmup'",
        ),
        "deep json": ([broken("deep", deep)], "manifest.json: is not valid JSON"),
        "not utf-8": ([broken("utf8", not_utf8)], "manifest.json: is not valid JSON"),
        "edited manifest": (
            [
                broken(
                    "edited",
                    lambda p: edit_manifest(p, _set("threshold", 9.0), resign=False),
                )
            ],
            f"field '{DIGEST_FIELD}'",
        ),
        "first call fails": (
            [broken("fails", lambda p: _swap_graph(p, _failing_graph()))],
            "model.onnx: onnxruntime refused it",
        ),
        "endless graph": (
            [
                broken("endless", lambda p: _swap_graph(p, _endless_graph())),
                "--load-deadline",
                "0.2",
            ],
            "model.onnx: onnxruntime did not finish",
        ),
        "rounds 0": ([b, "--choose-session", "--rounds", "0"], "--rounds"),
        "rounds text": ([b, "--choose-session", "--rounds", "abc"], "--rounds"),
        "choose on 2 frames": (
            [b, "--choose-session", "--frames", "2"],
            "no decision",
        ),
        "timeout -1": ([b, "--udp", "127.0.0.1:0", "--timeout", "-1"], "--timeout"),
        "timeout nan": ([b, "--udp", "127.0.0.1:0", "--timeout", "nan"], "--timeout"),
        "host not local": (
            [b, "--udp", "192.0.2.1:9000"],
            "--udp: cannot listen on '192.0.2.1'",
        ),
        "port too big": ([b, "--udp", "127.0.0.1:99999"], "--udp"),
        "resync 0": (
            [b, "--udp", "127.0.0.1:0", "--resync-after", "0"],
            "--resync-after",
        ),
        "deadline 0": ([b, "--load-deadline", "0"], "--load-deadline"),
        "frames 0": ([b, "--frames", "0"], "--frames"),
        "json is a folder": ([b, "--frames", "10", "--json", str(json_dir)], "--json"),
        "unknown option": ([b, "--fast"], "unrecognized arguments: --fast"),
        "no bundle": ([str(tmp / "nowhere")], "is not a bundle folder"),
    }


CASE_NAMES = [
    "truncated npz",
    "garbage npz",
    "noise",
    "1e11-row npy",
    "zip bomb",
    "scalar npy",
    "huge window",
    "huge baseline",
    "million threads",
    "endless warm-up",
    "deep json",
    "not utf-8",
    "edited manifest",
    "first call fails",
    "endless graph",
    "rounds 0",
    "rounds text",
    "choose on 2 frames",
    "timeout -1",
    "timeout nan",
    "host not local",
    "port too big",
    "resync 0",
    "deadline 0",
    "frames 0",
    "json is a folder",
    "unknown option",
    "no bundle",
]


@pytest.fixture(scope="module")
def cli_cases(
    base: LinearCase, tmp_path_factory: pytest.TempPathFactory
) -> dict[str, tuple[list[str], str]]:
    return _cases(tmp_path_factory.mktemp("cli-cases"), base)


@pytest.mark.parametrize("name", CASE_NAMES)
def test_slipkit_run_refuses_malformed_input_in_one_line(
    cli_cases: dict[str, tuple[list[str], str]],
    name: str,
    capfd: pytest.CaptureFixture[str],
) -> None:
    """Malformed files, manifests, graphs and options end in exit 2 and one stderr line naming the culprit."""
    argv, expected = cli_cases[name]
    with pytest.raises(SystemExit) as info:
        main(argv)
    err = capfd.readouterr().err
    assert 2 == info.value.code
    assert 1 == len(err.splitlines()), err
    assert err.startswith("slipkit-run: error: "), err
    assert expected in err
    assert "Traceback" not in err


def test_every_cli_case_is_exercised(
    cli_cases: dict[str, tuple[list[str], str]],
) -> None:
    """The parametrised list above covers every case built by _cases."""
    assert sorted(cli_cases) == sorted(CASE_NAMES)


# -- UDP: resynchronisation and the wall-clock timeout -----------------------------------
def _send(port: int, indices: list[int], values: np.ndarray) -> None:
    with UdpSender("127.0.0.1", port) as tx:
        for j, index in enumerate(indices):
            tx.send(index, j / 100.0, values[j % len(values)])


def _drain(src: UdpSource) -> list[int]:
    return [frame.frame_index for frame in src]


def test_udp_resyncs_after_a_stray_maximum_index(base: LinearCase) -> None:
    """One datagram with index 2^64-1 costs resync_after frames, not the rest of the run."""
    indices = [*range(10), 2**64 - 1, *range(10, 60)]
    with UdpSource("127.0.0.1", 0, (3,), timeout_s=0.5, resync_after=4) as src:
        _send(src.address[1], indices, base.frames)
        got = _drain(src)
    assert [*range(10), 2**64 - 1, *range(14, 60)] == got
    assert (57, 4, 0, 2) == (src.n_received, src.n_rejected, src.n_lost, src.n_resyncs)


def test_udp_resyncs_after_a_sender_restart(base: LinearCase) -> None:
    """A sensor bridge restarting at index 0 is followed after resync_after rejected frames."""
    indices = [*range(30), *range(30)]
    with UdpSource("127.0.0.1", 0, (3,), timeout_s=0.5, resync_after=3) as src:
        _send(src.address[1], indices, base.frames)
        got = _drain(src)
    assert [*range(30), *range(3, 30)] == got
    assert (57, 3, 0, 1) == (src.n_received, src.n_rejected, src.n_lost, src.n_resyncs)


def test_junk_datagrams_do_not_keep_the_timeout_alive() -> None:
    """A stream of junk datagrams does not reset --timeout: the source ends while the junk still flows."""
    stop = threading.Event()
    sent = []

    def junk(port: int) -> None:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as tx:
            # At most 10 s of junk; the fixed source times out long before.
            for _ in range(1000):
                if stop.is_set():
                    return
                tx.sendto(b"junk", ("127.0.0.1", port))
                sent.append(1)
                stop.wait(0.01)
        sent.append("exhausted")

    # Before the first frame the wait_s clock applies (--wait), after it timeout_s.
    with UdpSource("127.0.0.1", 0, (3,), timeout_s=0.3, wait_s=0.3) as src:
        thread = threading.Thread(target=junk, args=(src.address[1],), daemon=True)
        thread.start()
        got = _drain(src)
        still_sending = not stop.is_set() and "exhausted" not in sent
        stop.set()
        thread.join(timeout=15)
    assert ([], True, True) == (got, src.waited_out, still_sending)
    assert 0 < src.n_rejected


@pytest.mark.parametrize(
    ("kwargs", "option"),
    [
        ({"timeout_s": -1.0}, "timeout_s"),
        ({"timeout_s": math.nan}, "timeout_s"),
        ({"resync_after": 0}, "resync_after"),
        ({"max_frames": 0}, "max_frames"),
    ],
    ids=["timeout-negative", "timeout-nan", "resync-0", "frames-0"],
)
def test_udp_source_options_are_bounded(kwargs: dict[str, Any], option: str) -> None:
    """UdpSource refuses a negative or NaN timeout, a zero resync run, zero frames, naming the argument."""
    with pytest.raises(SlipkitError, match=f"^{option}: "):
        UdpSource("127.0.0.1", 0, (3,), **kwargs)


def test_slipkit_run_reports_resyncs(
    base: LinearCase, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """slipkit-run --udp prints and writes the resync count after a sender restart."""
    probe = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    probe.bind(("127.0.0.1", 0))
    port = probe.getsockname()[1]
    probe.close()
    out = tmp_path / "u.json"
    argv = [
        str(base.path),
        *("--udp", f"127.0.0.1:{port}", "--timeout", "1", "--resync-after", "2"),
        *("--json", str(out)),
    ]
    status: list[int] = []
    cli = threading.Thread(target=lambda: status.append(run(argv)), daemon=True)
    cli.start()
    for _ in range(500):  # until slipkit-run holds the port (at most 10 s)
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            try:
                s.bind(("127.0.0.1", port))
            except OSError:
                break
        threading.Event().wait(0.02)
    _send(port, [*range(20), *range(20)], base.frames)
    cli.join(timeout=30)
    udp = json.loads(out.read_text())["udp"]
    assert [0] == status
    assert (38, 2, 0, 1) == (
        udp["received"],
        udp["rejected"],
        udp["lost"],
        udp["resyncs"],
    )
    assert "38 received, 2 rejected, 0 lost, 1 resyncs" in capsys.readouterr().out


# -- property: any mutation of a valid manifest loads or is a BundleError -----------------
def _paths(obj: Any, prefix: tuple[Any, ...] = ()) -> list[tuple[Any, ...]]:
    """Every key / index path in a decoded manifest (inner nodes and leaves)."""
    out = [prefix] if prefix else []
    if isinstance(obj, dict):
        for k, v in obj.items():
            out += _paths(v, (*prefix, k))
    elif isinstance(obj, list):
        for i, v in enumerate(obj[:3]):
            out += _paths(v, (*prefix, i))
    return out


def _nested(depth: int) -> Any:
    value: Any = 1
    for _ in range(depth):
        value = [value]
    return value


junk_values = st.recursive(
    st.none()
    | st.booleans()
    | st.integers(-(2**70), 2**70)
    | st.sampled_from([0, -1, 1, 2**31, 2**63, 10**12, 10**30])
    | st.floats(allow_nan=True, allow_infinity=True)
    | st.sampled_from([math.nan, math.inf, -math.inf, 1e308, -0.0, 5e-324])
    | st.text(max_size=6),
    lambda inner: (
        st.lists(inner, max_size=4)
        | st.dictionaries(st.text(max_size=6), inner, max_size=3)
    ),
    max_leaves=8,
) | st.integers(20, 60).map(_nested)


@pytest.fixture(scope="module")
def mutable(base: LinearCase, tmp_path_factory: pytest.TempPathFactory) -> Path:
    return Path(shutil.copytree(base.path, tmp_path_factory.mktemp("prop") / "b"))


@settings(
    max_examples=150,
    deadline=None,
    suppress_health_check=[HealthCheck.function_scoped_fixture],
)
@given(data=st.data())
def test_any_mutated_manifest_loads_or_is_a_bundle_error(
    base: LinearCase, mutable: Path, data: st.DataObject
) -> None:
    """Dropping a key or putting junk (huge, negative, NaN, nested) anywhere: a clean load or a BundleError."""
    man = json.loads((base.path / "manifest.json").read_text())
    man.pop(DIGEST_FIELD)
    path = data.draw(st.sampled_from(_paths(man)), label="path")
    *parents, last = path
    obj: Any = man
    for p in parents:
        obj = obj[p]
    if data.draw(st.booleans(), label="drop") and isinstance(obj, dict):
        del obj[last]
    else:
        obj[last] = data.draw(junk_values, label="value")
    edit_manifest(mutable, lambda m: (m.clear(), m.update(man)))
    try:
        bundle = load_bundle(mutable, deadline_s=2.0)
    except BundleError as exc:
        refused = str(exc)
        event(f"refused: {str(exc.field).split('.')[0].split('[')[0]}")
    else:
        refused = ""
        event("loaded")
    if refused:
        assert 1 == len(refused.splitlines())
        return
    loop = StreamLoop(bundle)
    result = loop.run(_replay(base))
    assert 20 == result.n_frames


def _replay(base: LinearCase) -> ReplaySource:
    return ReplaySource(base.frames[:20], base.timestamps[:20])


# -- slipkit-run --json inside a slipkit folder ---------------------------------------------
@pytest.mark.parametrize(
    "target", ["bundle manifest", "dataset manifest", "inside run"]
)
def test_json_summary_never_lands_inside_a_slipkit_folder(
    bundle: Path,
    tmp_path: Path,
    target: str,
    capsys: pytest.CaptureFixture[str],
) -> None:
    """--json over a bundle's, dataset's or run's files is refused before any work; the file is untouched."""
    from tests.strategies import make_dataset

    from slipkit.data import save_dataset

    dataset = tmp_path / "ds"
    save_dataset(make_dataset(n_trials=2, n_frames=10, with_events=False), dataset)
    run_dir = tmp_path / "run"
    run_dir.mkdir()
    (run_dir / "run.json").write_text('{"format": "slipkit-run"}\n')
    path = {
        "bundle manifest": bundle / "manifest.json",
        "dataset manifest": dataset / "manifest.json",
        "inside run": run_dir / "summary.json",
    }[target]
    before = path.read_bytes() if path.exists() else None
    with pytest.raises(SystemExit) as info:
        main([str(bundle), "--frames", "10", "--json", str(path)])
    err = capsys.readouterr().err
    after = path.read_bytes() if path.exists() else None
    assert (2, True, True, before) == (
        info.value.code,
        err.startswith("slipkit-run: error: --json="),
        "refusing to write into it" in err,
        after,
    )
