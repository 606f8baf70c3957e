"""The bundle format: ``exports/<name>/`` = ``model.onnx`` + ``manifest.json`` (+ ``replay.npz``, ``MODEL_CARD.md``).

A bundle is everything a gripper PC needs to decide slip from raw sensor frames: the
ONNX graph, the numpy preprocessing the graph does not hold (a closed registry of
named ops, :mod:`slipkit.runtime.preprocessing`), the decision rule, the debounce, the
latency budget and the session options. Loading never executes code from the bundle
(JSON and ONNX only; no pickle anywhere) and checks the manifest's own digest, its
types and bounds, and the sha256 of every listed file before an onnxruntime session
is created; the graph's first call then runs under a deadline.

Manifest schema, version 3 (every field is described in ``docs/deploy.md``)::

    {
      "format": "slipkit-bundle", "schema_version": 3, "name": "tactip_svm",
      "description": "optional free text",
      "frame": {"streams": ["pins"], "channels": ["x0", ..., "y126"], "shape": [254],
                "window": 2, "hop": 1, "rate_hz": 120.0},
      "preprocessing": [{"op": "pin_velocity_features", "variant": "dr_dtheta"},
                        {"op": "standardize", "mean": [...], "scale": [...]}],
      "inputs": [{"name": "X", "dtype": "float32", "shape": [1, 254]}],
      "outputs": [{"name": "label"},
                  {"name": "score", "dtype": "float32", "shape": [1, 1]}],
      "decision": {"output": "score", "rule": "threshold", "column": 0,
                   "classes": ["static", "slip"], "positive": "slip",
                   "strict": false},
      "threshold": 0.0,
      "debounce": {"k": 2},
      "budget_ms": {"frame_period": 8.333, "p99": 0.833,
                    "source": "data_rate_hz"},
      "session": {"intra_op_num_threads": 1, "inter_op_num_threads": 1,
                  "graph_optimization_level": "all", "allow_spinning": false,
                  "warmup": 20},
      "opset": 17,
      "producer": {"slipkit": "0.1.0", "onnx": "1.23.2", "skl2onnx": "1.19.1"},
      "training": {"data_fingerprint": "…", "metrics": {"test": {"f1": 0.97}},
                   "refit_on_all_data": false, "scored_on": "…", "held_out": true,
                   "replay": {"trials": 12, "frames": 3000, "held_out": true,
                              "by_class": {"slip": 6, "static": 6}, "note": "…"}},
      "files": {"model.onnx": "<sha256 hex>", "replay.npz": "<sha256 hex>"},
      "manifest_sha256": "<sha256 hex of the canonical manifest>"
    }

Version 2 added ``manifest_sha256`` (:func:`manifest_digest`: the sha256 of the
manifest without that field, as JSON with sorted keys and no whitespace), bounds on
every number (:mod:`slipkit.runtime._schema`, ``MAX_*``), and output ``shape``
entries that may be ``null`` (a symbolic dimension); :func:`write_bundle` records the
dtype and shape of every listed output from the graph. The digest catches an edited
or damaged manifest (corruption, a partial copy, a hand edit that forgets it); it is
a checksum, not a signature: whoever can write the folder can recompute it. Against
that, :func:`write_bundle` with a ``key`` adds ``manifest.hmac``
(:data:`SIGNATURE_FILE`: :func:`manifest_hmac`, the HMAC-SHA256 of ``manifest.json``'s
bytes under a key the lab keeps), which :func:`load_bundle` with that ``key`` checks
first.

Version 3 added, for a multi-class model, ``decision.slip_classes`` (the argmax rule:
slip when the largest score entry is any of these classes, e.g. every direction of
slip against ``t``, touch; one class is still ``positive``), ``budget_ms.source``
(``data_rate_hz``: the frame period is ``1000 / frame.rate_hz``; ``sensor_default``:
the sensor family's ``configs/deploy`` value, used when the data has no rate) and
checked provenance in ``training`` (``refit_on_all_data``, ``scored_on``,
``held_out``, ``replay``). This runtime reads versions 2 and 3
(:data:`READ_VERSIONS`); the digest covers every field of both.

Recurrent state (optional ``state``, no version bump: a bundle without it reads as
before, and a runtime that does not know the field refuses it as unknown rather than
running a recurrent graph from a zero state every frame)::

      "state": [{"input": "h_in", "output": "h_out", "shape": [1, 16],
                 "dtype": "float32"}]

Each entry names a graph input the loop feeds besides the frame input and the graph
output that holds its next value; :class:`~slipkit.runtime.loop.StreamLoop` starts it
at zeros, carries the output into the input after every scored frame and sets it back
to zeros on a gap, a bad frame, a window skipped as non-finite and ``reset()``
(``docs/deploy.md``, "Recurrent state"). At most :data:`MAX_STATE` entries, each of
at most ``MAX_VALUES`` values; the names must be graph inputs / outputs of that shape
and dtype (checked at load).

Prepared decisions (optional ``prepare``, no version bump, as ``state``)::

      "prepare": {"tensor": "partial"},
      "files": {"model.onnx": "…", "prepare.onnx": "…", ...}

A second graph, ``prepare.onnx`` (listed in ``files``), takes the same input as
``model.onnx`` (``inputs[0]``) and has one output, named ``tensor``; the main graph has
a second input of that name, dtype and shape. :class:`~slipkit.runtime.loop.StreamLoop`
runs the prepare graph on the frame *before* each decision, on that frame's window,
and feeds its output to the main graph at the decision: work that does not need the
newest frame is done one frame early, and the decision frame's latency holds only the
rest (the SlipTack speed graph: the spectrum of the window with its newest sample held,
``docs/deploy.md``, "SlipTack: a prepared spectrum"). Not with ``state`` or
``preprocessing`` steps (a stateful step would see every window twice).

Model card (optional ``MODEL_CARD.md``, :data:`CARD_FILE`, no version bump): Markdown
that ``slipkit export`` writes (:mod:`slipkit.export.card`), listed in ``files`` and so
checked like the graph; :meth:`Bundle.card` returns its text, None for a bundle
without one.
"""

from __future__ import annotations

import hashlib
import hmac
import json
import math
import re
import threading
from collections.abc import Mapping
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
import onnxruntime as ort

from slipkit._files import atomic_dir, recover_leftovers, sha256_bytes, sha256_file
from slipkit.runtime._schema import (
    MAX_DEBOUNCE_K,
    MAX_FRAME_PERIOD_MS,
    MAX_FRAMES,
    MAX_JSON_DEPTH,
    MAX_MANIFEST_BYTES,
    MAX_MODEL_BYTES,
    MAX_OPSET,
    MAX_RATE_HZ,
    MAX_VALUES,
    Fields,
    json_depth,
)
from slipkit.runtime.errors import BundleError, OptionError
from slipkit.runtime.preprocessing import Pipeline
from slipkit.runtime.session import ORT_ERRORS, SessionSpec, make_session

FORMAT = "slipkit-bundle"
SCHEMA_VERSION = 3
#: Schema versions this runtime reads (2: one slip class; 3 adds the fields above).
READ_VERSIONS = (2, 3)
#: Where ``budget_ms.frame_period`` came from (schema 3).
BUDGET_SOURCES = ("data_rate_hz", "sensor_default")
#: Longest free-text provenance field checked in ``training`` (characters).
MAX_TEXT = 4096
MODEL_FILE = "model.onnx"
MANIFEST_FILE = "manifest.json"
#: The manifest field holding :func:`manifest_digest` of the rest of the manifest.
DIGEST_FIELD = "manifest_sha256"
#: Seconds the graph's first call (at load) may take before the load is refused.
DEFAULT_DEADLINE_S = 5.0
#: Longest load deadline accepted, s.
MAX_DEADLINE_S = 3600.0
#: Recorded frames an exporter may add for ``slipkit-run <bundle>`` and session tuning.
REPLAY_FILE = "replay.npz"
#: HMAC-SHA256 of manifest.json's bytes under a key the lab keeps (optional).
SIGNATURE_FILE = "manifest.hmac"
#: Largest key file read, bytes.
MAX_KEY_BYTES = 1 << 16

TOP_FIELDS = (
    "format",
    "schema_version",
    "name",
    "description",
    "frame",
    "preprocessing",
    "inputs",
    "outputs",
    "decision",
    "threshold",
    "debounce",
    "budget_ms",
    "session",
    "opset",
    "producer",
    "training",
    "files",
    "state",
    "prepare",
    DIGEST_FIELD,
)
#: The prepare graph's file (manifest ``prepare``).
PREPARE_FILE = "prepare.onnx"
#: The model card ``slipkit export`` writes beside the manifest (Markdown, listed in
#: ``files``); a bundle without one still loads.
CARD_FILE = "MODEL_CARD.md"
#: Largest model card :meth:`Bundle.card` reads.
MAX_CARD_BYTES = 1 << 20
#: Most recurrent state tensors (``state`` entries) a bundle may carry.
MAX_STATE = 8
#: dtypes a state tensor may have (the loop keeps it in a numpy buffer of that dtype).
STATE_DTYPES = ("float32", "float64")
#: Graph input dtypes the loop can feed (ONNX type string -> manifest name).
INPUT_DTYPES = {"tensor(float)": "float32", "tensor(double)": "float64"}
#: ONNX type strings of outputs the decision can read.
SCORE_DTYPES = {"tensor(float)": "float32", "tensor(double)": "float64"}
#: ONNX tensor element type -> manifest dtype name (numpy's), for the output check.
ONNX_DTYPES = {
    "float": "float32",
    "double": "float64",
    "float16": "float16",
    "bool": "bool",
    "string": "string",
    **{t: t for t in ("int8", "int16", "int32", "int64")},
    **{t: t for t in ("uint8", "uint16", "uint32", "uint64")},
}
_SHA256 = re.compile(r"^[0-9a-f]{64}$")
_FILE_NAME = re.compile(r"^[A-Za-z0-9_.-]+$")


@dataclass(frozen=True)
class FrameSpec:
    """What one sensor frame is and how frames make a model window.

    Attributes
    ----------
    streams : tuple of str
        Dataset streams the frame's values come from (``("pins",)``).
    channels : tuple of str
        Channel names, one per value, in frame order (flattened C order of ``shape``).
    shape : tuple of int
        Shape of one frame (``(254,)``, or ``(H, W)`` for an image).
    window : int
        Frames per model call, oldest first.
    hop : int
        Frames between model calls (1 = decide on every frame).
    rate_hz : float
        Sensor frame rate, Hz.
    """

    streams: tuple[str, ...]
    channels: tuple[str, ...]
    shape: tuple[int, ...]
    window: int
    hop: int
    rate_hz: float

    @property
    def n_values(self) -> int:
        """Values per frame."""
        return math.prod(self.shape)


@dataclass(frozen=True)
class TensorSpec:
    """A graph input or output: name, dtype (``float32``...) and shape (None: unchecked).

    An output's shape may hold None for a symbolic dimension; an input's never does.
    """

    name: str
    dtype: str | None
    shape: tuple[int | None, ...] | None

    @property
    def static_shape(self) -> tuple[int, ...]:
        """The shape with every dimension known (an input's, checked at validation)."""
        if self.shape is None or any(d is None for d in self.shape):
            raise ValueError(f"tensor {self.name!r} has no static shape: {self.shape}")
        return tuple(int(d) for d in self.shape if d is not None)


@dataclass(frozen=True)
class StateSpec:
    """One recurrent state tensor the loop carries between frames (manifest ``state``).

    Attributes
    ----------
    input : str
        Graph input fed the state (zeros at the start and after a reset).
    output : str
        Graph output holding the next state (fed back after every scored frame).
    shape : tuple of int
        Static shape of both.
    dtype : {"float32", "float64"}
        Their element type.
    """

    input: str
    output: str
    shape: tuple[int, ...]
    dtype: str


def onnx_dtype(type_str: str) -> str:
    """The manifest dtype of an onnxruntime type string (``tensor(float)`` -> ``float32``).

    A non-tensor type (``seq(map(int64,tensor(float)))``) is returned unchanged.
    """
    if type_str.startswith("tensor(") and type_str.endswith(")"):
        elem = type_str[len("tensor(") : -1]
        return ONNX_DTYPES.get(elem, elem)
    return type_str


def manifest_digest(manifest: Mapping[str, Any]) -> str:
    """sha256 hex of a manifest's canonical JSON, without its ``manifest_sha256`` field.

    Canonical: sorted keys, no whitespace, ASCII escapes (a NaN is written ``NaN``;
    :func:`validate_manifest` refuses it), so the digest depends on the decoded
    values only, not on how the file was indented.

    Raises
    ------
    ValueError
        A value JSON cannot hold.
    """
    body = {k: v for k, v in manifest.items() if k != DIGEST_FIELD}
    text = json.dumps(body, sort_keys=True, separators=(",", ":"))
    return sha256_bytes(text.encode("ascii"))


def manifest_hmac(manifest_bytes: bytes, key: bytes) -> str:
    """HMAC-SHA256 hex of ``manifest.json``'s bytes under ``key`` (``manifest.hmac``).

    The manifest lists the sha256 of every other file, so the HMAC covers the whole
    bundle; unlike ``manifest_sha256``, only a holder of the key can make one.
    """
    return hmac.new(key, manifest_bytes, hashlib.sha256).hexdigest()


def read_key(
    path: str | Path, option: str, *, bundles: tuple[str | Path, ...] = ()
) -> bytes:
    """The bytes of a key file (``slipkit-run --key``, ``slipkit export sign_key=``).

    Refused with an :class:`OptionError` naming ``option``: a path that is not a
    readable file, an empty file, one over :data:`MAX_KEY_BYTES`, or one inside any
    of ``bundles`` (a key shipped with the bundle proves nothing).
    """
    p = Path(path)
    try:
        real = p.resolve()
        for folder in bundles:
            if real.is_relative_to(Path(folder).resolve()):
                raise OptionError(
                    option,
                    f"{p} is inside the bundle {folder}: keep the key outside it "
                    "(a key shipped with the bundle signs anything)",
                )
        if not p.is_file():
            raise OptionError(option, f"{p} is not a file")
        size = p.stat().st_size
        if size > MAX_KEY_BYTES:
            raise OptionError(
                option, f"{p} is {size} bytes; a key file holds at most {MAX_KEY_BYTES}"
            )
        key = p.read_bytes()
    except (OSError, ValueError) as exc:  # ValueError: a NUL in the path
        why = exc.strerror if isinstance(exc, OSError) and exc.strerror else exc
        raise OptionError(option, f"cannot read {p}: {why}") from None
    if not key:
        raise OptionError(option, f"{p} is empty; a key file holds the key's bytes")
    return key


def _check_hmac(root: Path, manifest_bytes: bytes, key: bytes) -> None:
    """``manifest.hmac`` exists and is the HMAC of ``manifest_bytes`` under ``key``."""
    sig = root / SIGNATURE_FILE
    where = str(sig)
    try:
        if not sig.is_file():
            raise BundleError(
                where,
                None,
                "is missing: the bundle is not signed, and a key was given (export "
                "it with sign_key=<key file>)",
            )
        if sig.stat().st_size > 1024:
            raise BundleError(where, None, "is over 1024 bytes: not a signature")
        given = sig.read_bytes().strip().decode("ascii", "replace")
    except OSError as exc:
        raise BundleError(
            where, None, f"cannot be read: {exc.strerror or exc}"
        ) from None
    if not hmac.compare_digest(given, manifest_hmac(manifest_bytes, key)):
        raise BundleError(
            where,
            None,
            f"does not match {MANIFEST_FILE} under the given key: the manifest was "
            "changed after signing, or signed with another key",
        )


def sign_manifest(manifest: Mapping[str, Any]) -> dict[str, Any]:
    """A copy of ``manifest`` with ``manifest_sha256`` set to :func:`manifest_digest`."""
    return {**manifest, DIGEST_FIELD: manifest_digest(manifest)}


@dataclass(frozen=True)
class DecisionSpec:
    """How the score output becomes a per-frame slip decision.

    Attributes
    ----------
    output : str
        Graph output that holds the score.
    rule : {"threshold", "argmax"}
        ``threshold``: the score is *above* when ``score[column] >= threshold``
        (``>`` when ``strict``); above means ``classes[1]`` and below ``classes[0]``
        (scikit-learn's binary ``decision_function`` convention), and slip is
        declared when that class is ``positive`` (without ``classes``: above is
        slip). ``argmax``: slip when the largest entry is the positive class.
    column : int
        Entry of the flattened score output compared with the threshold
        (``argmax``: the positive class's index, derived from ``classes``).
    classes : tuple of str or None
        Class names in output order (required for ``argmax``).
    positive : str or None
        The slip class (required when ``classes`` is given).
    threshold : float or None
        The manifest's top-level ``threshold`` (``threshold`` rule only).
    strict : bool
        Compare with ``>`` instead of ``>=`` (scikit-learn's ``predict`` uses
        ``decision_function > 0``).
    slip_columns : tuple of int
        ``argmax``: the score entries of every slip class (``decision.slip_classes``,
        schema 3; else the positive class's alone). Empty for the threshold rule.
    """

    output: str
    rule: str
    column: int
    classes: tuple[str, ...] | None
    positive: str | None
    threshold: float | None
    strict: bool = False
    slip_columns: tuple[int, ...] = ()

    @property
    def slip_classes(self) -> tuple[str, ...]:
        """The classes a decision counts as slip (``()`` without classes: above is slip)."""
        if self.classes is None:
            return ()
        if self.rule == "argmax":
            return tuple(self.classes[c] for c in self.slip_columns)
        assert self.positive is not None
        return (self.positive,)

    @property
    def slip_above(self) -> bool:
        """Whether a score at or above the threshold means slip (threshold rule)."""
        return self.classes is None or self.positive == self.classes[1]


@dataclass(frozen=True)
class Budget:
    """Latency budget per decision, ms: the sensor's frame period and the p99 target.

    ``source`` says where the frame period came from (:data:`BUDGET_SOURCES`; None
    in a schema-2 manifest, which does not say).
    """

    frame_period_ms: float
    p99_ms: float
    source: str | None = None


@dataclass(frozen=True)
class Manifest:
    """A checked ``manifest.json`` (see the module docstring for the JSON layout).

    Attributes
    ----------
    name : str
        Bundle name.
    frame : FrameSpec
        Frame and window spec.
    preprocessing : tuple of dict
        Steps run in numpy before the graph.
    inputs, outputs : tuple of TensorSpec
        The graph's input (exactly one) and the outputs the manifest describes.
    decision : DecisionSpec
        Score -> decision rule (holds the threshold).
    debounce_k : int
        Consecutive slip decisions before slip is declared.
    budget : Budget
        Latency budget, ms.
    session : SessionSpec
        onnxruntime options.
    opset : int
        ONNX default-domain opset of the graph.
    producer : dict of str
        Versions of the tools that wrote the bundle.
    training : dict
        Training data fingerprint and metrics (free JSON, recorded for provenance).
    files : dict of str
        File name -> sha256 hex, ``model.onnx`` always among them.
    raw : dict
        The decoded JSON as read.
    state : tuple of StateSpec
        Recurrent state the loop carries between frames (``()``: none).
    prepare : str or None
        The tensor ``prepare.onnx`` hands to the main graph (None: no prepare graph).
    """

    name: str
    frame: FrameSpec
    preprocessing: tuple[dict[str, Any], ...]
    inputs: tuple[TensorSpec, ...]
    outputs: tuple[TensorSpec, ...]
    decision: DecisionSpec
    debounce_k: int
    budget: Budget
    session: SessionSpec
    opset: int
    producer: dict[str, str]
    training: dict[str, Any]
    files: dict[str, str]
    raw: dict[str, Any]
    state: tuple[StateSpec, ...] = ()
    prepare: str | None = None


def _output_shape(f: Fields) -> tuple[int | None, ...]:
    """An output's shape: a list of dims in [1, MAX_VALUES] or null (symbolic)."""
    value = f.raw("shape")
    if (
        not isinstance(value, list)
        or len(value) > 32
        or not all(
            v is None
            or (isinstance(v, int) and not isinstance(v, bool) and 1 <= v <= MAX_VALUES)
            for v in value
        )
    ):
        raise f.error(
            "shape",
            f"must be a list of at most 32 dims, each an integer in [1, {MAX_VALUES}] "
            "or null (symbolic)",
        )
    return tuple(value)


def _first_nonfinite(obj: dict[str, Any]) -> str | None:
    """Dotted path of the first NaN or infinity in a decoded manifest, or None."""
    stack: list[tuple[Any, str]] = [(obj, "")]
    while stack:
        value, path = stack.pop()
        if isinstance(value, float) and not math.isfinite(value):
            return path
        if isinstance(value, dict):
            stack.extend(
                (v, f"{path}.{k}" if path else str(k)) for k, v in value.items()
            )
        elif isinstance(value, list):
            stack.extend((v, f"{path}[{i}]") for i, v in enumerate(value))
    return None


def _tensors(top: Fields, key: str, *, need_shape: bool) -> tuple[TensorSpec, ...]:
    value = top.raw(key)
    if not isinstance(value, list) or not value:
        raise top.error(key, "must be a non-empty list of {name, dtype, shape} objects")
    if len(value) > 64:
        raise top.error(key, f"lists {len(value)} tensors; at most 64")
    specs = []
    for i, item in enumerate(value):
        f = Fields(top.file, item, f"{key}[{i}]")
        f.only(("name", "dtype", "shape"))
        dtype = f.raw("dtype", None)
        if dtype is not None:
            dtype = f.string("dtype")
        shape: tuple[int | None, ...] | None = None
        if need_shape:  # an input: static dims only
            shape = f.integers("shape", max_product=MAX_VALUES)
        elif "shape" in f.obj:
            shape = _output_shape(f)
        specs.append(TensorSpec(f.string("name"), dtype, shape))
    names = [s.name for s in specs]
    if len(set(names)) != len(names):
        raise top.error(key, f"names must be unique; got {names}")
    return tuple(specs)


def _state(
    top: Fields, inputs: tuple[TensorSpec, ...], decision_output: str
) -> tuple[StateSpec, ...]:
    """The optional ``state`` list (see the module docstring), checked without the graph."""
    value = top.raw("state", [])
    if not isinstance(value, list):
        raise top.error(
            "state", "must be a list of {input, output, shape, dtype} objects"
        )
    if len(value) > MAX_STATE:
        raise top.error("state", f"lists {len(value)} tensors; at most {MAX_STATE}")
    specs: list[StateSpec] = []
    for i, item in enumerate(value):
        f = Fields(top.file, item, f"state[{i}]")
        f.only(("input", "output", "shape", "dtype"))
        spec = StateSpec(
            input=f.string("input"),
            output=f.string("output"),
            shape=f.integers("shape", max_product=MAX_VALUES),
            dtype=f.string("dtype", choices=STATE_DTYPES),
        )
        if spec.input == inputs[0].name:
            raise f.error(
                "input", f"{spec.input!r} is the frame input inputs[0]; name another"
            )
        if spec.output == decision_output:
            raise f.error(
                "output",
                f"{spec.output!r} is the score output decision.output; name another",
            )
        for key in ("input", "output"):
            if any(getattr(s, key) == getattr(spec, key) for s in specs):
                raise f.error(key, f"{getattr(spec, key)!r} is named twice in state")
        specs.append(spec)
    return tuple(specs)


def _prepare(
    top: Fields,
    inputs: tuple[TensorSpec, ...],
    decision_output: str,
    state: tuple[StateSpec, ...],
    steps: list[dict[str, Any]],
    files: dict[str, str],
) -> str | None:
    """The optional ``prepare`` object (module docstring), checked without the graphs."""
    if "prepare" not in top.obj:
        if PREPARE_FILE in files:
            raise top.error(
                f"files.{PREPARE_FILE}",
                "is listed but the manifest has no 'prepare' field naming its tensor",
            )
        return None
    f = top.child("prepare")
    f.only(("tensor",))
    tensor = f.string("tensor")
    if tensor in (inputs[0].name, decision_output):
        raise f.error(
            "tensor",
            f"{tensor!r} is the frame input or the score output; name another",
        )
    if state:
        raise f.error("tensor", "a bundle has either 'prepare' or 'state', not both")
    if steps:
        raise f.error(
            "tensor",
            "needs an empty 'preprocessing': the prepare graph reads the window "
            "the main graph reads, one frame early",
        )
    if PREPARE_FILE not in files:
        raise top.error(
            "files", f"has no {PREPARE_FILE!r} entry but the manifest has 'prepare'"
        )
    return tensor


def _frame(f: Fields) -> FrameSpec:
    f.only(("streams", "channels", "shape", "window", "hop", "rate_hz"))
    spec = FrameSpec(
        streams=f.strings("streams"),
        channels=f.strings("channels", unique=True),
        shape=f.integers("shape", max_product=MAX_VALUES),
        window=f.integer("window", minimum=1, maximum=MAX_FRAMES),
        hop=f.integer("hop", 1, minimum=1, maximum=MAX_FRAMES),
        rate_hz=f.number("rate_hz", positive=True, maximum=MAX_RATE_HZ),
    )
    # shape against channels first: a shape that disagrees is named there, not as
    # a window too large for it
    if spec.n_values != len(spec.channels):
        raise f.error(
            "channels",
            f"has {len(spec.channels)} names but frame.shape {list(spec.shape)} holds "
            f"{spec.n_values} values (one name per value)",
        )
    if spec.window * spec.n_values > MAX_VALUES:
        raise f.error(
            "window",
            f"{spec.window} frames of {spec.n_values} values exceed the {MAX_VALUES} "
            "values a window may hold",
        )
    return spec


def _slip_columns(
    f: Fields, classes: tuple[str, ...] | None, positive: str | None
) -> tuple[int, ...]:
    """The argmax rule's slip-class indices: ``slip_classes`` (schema 3) or ``positive``."""
    if "slip_classes" not in f.obj:
        assert classes is not None
        assert positive is not None
        return (classes.index(positive),)
    assert classes is not None  # the argmax rule requires classes
    slip = f.strings("slip_classes", unique=True)
    unknown = [c for c in slip if c not in classes]
    if unknown:
        raise f.error(
            "slip_classes",
            f"names {_short_list(unknown)} that decision.classes does not list "
            f"({_short_list(classes)})",
        )
    if positive not in slip:
        raise f.error(
            "slip_classes",
            f"must hold decision.positive {positive!r}; got {_short_list(slip)}",
        )
    return tuple(classes.index(c) for c in slip)


def _short_list(names: Any, limit: int = 8) -> str:
    """``[a, b, ...]`` with at most ``limit`` names (a message stays one short line)."""
    names = list(names)
    shown = ", ".join(repr(n)[:40] for n in names[:limit])
    return f"[{shown}{', ...' if len(names) > limit else ''}]"


def _decision(
    top: Fields, outputs: tuple[TensorSpec, ...], version: int = SCHEMA_VERSION
) -> DecisionSpec:
    f = top.child("decision")
    allowed = ["output", "rule", "column", "classes", "positive", "strict"]
    if version >= 3:
        allowed.append("slip_classes")
    f.only(allowed)
    names = [o.name for o in outputs]
    output = f.string("output", choices=names)
    rule = f.string("rule", choices=("threshold", "argmax"))
    classes = f.strings("classes", unique=True) if "classes" in f.obj else None
    positive = None
    if classes is not None:
        positive = f.string("positive", choices=classes)
    elif "positive" in f.obj:
        raise f.error("positive", "needs decision.classes to name the classes")
    slip_columns: tuple[int, ...] = ()
    if rule == "argmax":
        if classes is None:
            raise f.error(
                "classes", "is required for the argmax rule (one name per score entry)"
            )
        if "column" in f.obj:
            raise f.error(
                "column", "is not used by the argmax rule (the positive class fixes it)"
            )
        assert positive is not None
        column = classes.index(positive)
        slip_columns = _slip_columns(f, classes, positive)
        if top.raw("threshold", None) is not None:
            raise top.error("threshold", "must be null or absent for the argmax rule")
        threshold = None
        if "strict" in f.obj:
            raise f.error("strict", "is not used by the argmax rule")
    else:
        column = f.integer("column", 0, minimum=0, maximum=MAX_VALUES - 1)
        if classes is not None and len(classes) != 2:
            raise f.error(
                "classes",
                f"the threshold rule has two classes (negative, positive); got {list(classes)}",
            )
        threshold = top.number("threshold")
        if "slip_classes" in f.obj:
            raise f.error(
                "slip_classes",
                "is used by the argmax rule only (the threshold rule's slip class is "
                "decision.positive)",
            )
    strict = f.boolean("strict", False)
    return DecisionSpec(
        output, rule, column, classes, positive, threshold, strict, slip_columns
    )


def _training(top: Fields, version: int) -> dict[str, Any]:
    """The ``training`` object: free provenance JSON, with its schema-3 fields checked."""
    training = top.child("training", {})
    if "data_fingerprint" in training.obj:
        training.string("data_fingerprint")
    if "metrics" in training.obj:
        training.child("metrics")
    if version < 3:
        return dict(training.obj)
    for key in ("refit_on_all_data", "held_out"):
        if key in training.obj:
            training.boolean(key)
    if "scored_on" in training.obj:
        _text(training, "scored_on")
    if "replay" in training.obj:
        rep = training.child("replay")
        rep.only(("trials", "frames", "held_out", "by_class", "note"))
        rep.integer("trials", minimum=0, maximum=MAX_FRAMES)
        rep.integer("frames", minimum=0, maximum=MAX_VALUES)
        rep.boolean("held_out")
        if "note" in rep.obj:
            _text(rep, "note")
        if "by_class" in rep.obj:
            by = rep.child("by_class")
            if len(by.obj) > MAX_FRAMES:
                raise rep.error("by_class", f"lists more than {MAX_FRAMES} classes")
            for cls in by.obj:
                by.integer(cls, minimum=0, maximum=MAX_FRAMES)
    return dict(training.obj)


def _text(f: Fields, key: str) -> str:
    """A non-empty string of at most :data:`MAX_TEXT` characters."""
    value = f.string(key)
    if len(value) > MAX_TEXT:
        raise f.error(key, f"is {len(value)} characters long; at most {MAX_TEXT}")
    return value


def validate_manifest(obj: object, file: str = MANIFEST_FILE) -> Manifest:
    """Check a decoded manifest against schema version 2 or 3 (types, bounds, cross-field rules).

    Parameters
    ----------
    obj : object
        The decoded JSON.
    file : str
        File name used in error messages.

    Returns
    -------
    Manifest
        The typed, checked manifest. Checks that need the graph (input/output
        names and shapes, the preprocessing output size) are done by
        :func:`load_bundle`.

    Raises
    ------
    BundleError
        Naming ``file`` and the field at fault.

    Notes
    -----
    ``manifest_sha256`` is only type-checked here (64 lower-case hex digits);
    :func:`load_bundle` requires it and compares it with :func:`manifest_digest`.
    """
    top = Fields(file, obj)
    depth = json_depth(obj)
    if depth > MAX_JSON_DEPTH:
        raise top.error(
            None, f"is nested {depth} levels deep; at most {MAX_JSON_DEPTH}"
        )
    fmt = top.raw("format")
    if fmt != FORMAT:
        raise top.error(
            "format", f"must be {FORMAT!r}; got {fmt!r} (not a slipkit bundle)"
        )
    version = top.integer("schema_version")
    if version not in READ_VERSIONS:
        raise top.error(
            "schema_version",
            f"this runtime reads versions {', '.join(map(str, READ_VERSIONS))}; got {version} "
            "(re-export the bundle with this slipkit, or install the slipkit version "
            "that wrote it)",
        )
    top.only(TOP_FIELDS)
    name = top.string("name")
    if "description" in top.obj:
        top.string("description")
    frame = _frame(top.child("frame"))
    steps = top.raw("preprocessing", [])
    if not isinstance(steps, list):
        raise top.error("preprocessing", "must be a list of {op: ..., ...} steps")
    inputs = _tensors(top, "inputs", need_shape=True)
    if len(inputs) != 1:
        raise top.error(
            "inputs", f"must describe exactly one graph input; got {len(inputs)}"
        )
    if inputs[0].dtype not in INPUT_DTYPES.values():
        raise top.error(
            "inputs[0].dtype",
            f"must be one of {sorted(INPUT_DTYPES.values())}; got {inputs[0].dtype!r}",
        )
    outputs = _tensors(top, "outputs", need_shape=False)
    decision = _decision(top, outputs, version)
    deb = top.child("debounce")
    deb.only(("k",))
    budget_f = top.child("budget_ms")
    budget_f.only(
        ("frame_period", "p99", "source") if version >= 3 else ("frame_period", "p99")
    )
    budget = Budget(
        budget_f.number("frame_period", positive=True, maximum=MAX_FRAME_PERIOD_MS),
        budget_f.number("p99", positive=True, maximum=MAX_FRAME_PERIOD_MS),
        budget_f.string("source", choices=BUDGET_SOURCES)
        if "source" in budget_f.obj
        else None,
    )
    if budget.source == "data_rate_hz":
        want = 1000.0 / frame.rate_hz
        if abs(budget.frame_period_ms - want) > 1e-6 * want:
            raise budget_f.error(
                "frame_period",
                f"is {budget.frame_period_ms:g} ms but budget_ms.source is data_rate_hz "
                f"and frame.rate_hz {frame.rate_hz:g} Hz gives {want:g} ms",
            )
    if budget.p99_ms > budget.frame_period_ms:
        raise budget_f.error(
            "p99",
            f"must not exceed the frame period ({budget.frame_period_ms} ms); got {budget.p99_ms}",
        )
    session = SessionSpec.from_fields(top.child("session", {}))
    opset = top.integer("opset", minimum=1, maximum=MAX_OPSET)
    prod = top.child("producer")
    producer = {k: prod.string(k) for k in prod.obj}
    training = _training(top, version)
    files_f = top.child("files")
    files: dict[str, str] = {}
    for fname in files_f.obj:
        if not _FILE_NAME.match(fname) or fname in {".", "..", MANIFEST_FILE}:
            raise files_f.error(
                fname, "must be a plain file name inside the bundle folder"
            )
        digest = files_f.string(fname)
        if not _SHA256.match(digest):
            raise files_f.error(
                fname, f"must be a 64-digit lower-case sha256 hex; got {digest!r}"
            )
        files[fname] = digest
    if MODEL_FILE not in files:
        raise files_f.error(
            MODEL_FILE, "is missing (required): the sha256 of the graph"
        )
    nonfinite = _first_nonfinite(top.obj)
    if nonfinite is not None:
        raise top.error(
            nonfinite, "holds NaN or an infinity; a manifest is strict JSON"
        )
    if DIGEST_FIELD in top.obj:
        digest = top.string(DIGEST_FIELD)
        if not _SHA256.match(digest):
            raise top.error(
                DIGEST_FIELD,
                f"must be a 64-digit lower-case sha256 hex; got {digest!r}",
            )
    state = _state(top, inputs, decision.output)
    prepare = _prepare(top, inputs, decision.output, state, steps, files)
    return Manifest(
        state=state,
        prepare=prepare,
        name=name,
        frame=frame,
        preprocessing=tuple(steps),
        inputs=inputs,
        outputs=outputs,
        decision=decision,
        debounce_k=deb.integer("k", minimum=1, maximum=MAX_DEBOUNCE_K),
        budget=budget,
        session=session,
        opset=opset,
        producer=producer,
        training=training,
        files=files,
        raw=dict(top.obj),
    )


@dataclass(frozen=True)
class Bundle:
    """A loaded, checked bundle with its onnxruntime session.

    Attributes
    ----------
    path : Path
        The bundle folder.
    manifest : Manifest
        The checked manifest.
    model : bytes
        The ONNX graph (its sha256 matched the manifest).
    session : onnxruntime.InferenceSession
        Built with ``manifest.session`` (or the override given to :func:`load_bundle`).
    session_spec : SessionSpec
        The options ``session`` was built with.
    preprocessing : Pipeline
        The compiled preprocessing for ``(window, *frame.shape)``.
    deadline_s : float
        The load deadline, s: the graph's first call had to end within it, and the
        loop's warm-up stops once it has taken that long.
    prepare_model : bytes
        ``prepare.onnx`` (``b""`` without a ``prepare`` field).
    prepare_session : onnxruntime.InferenceSession or None
        Its session, built with the same options as ``session``.
    """

    path: Path
    manifest: Manifest
    model: bytes
    session: ort.InferenceSession
    session_spec: SessionSpec
    preprocessing: Pipeline
    deadline_s: float = DEFAULT_DEADLINE_S
    prepare_model: bytes = b""
    prepare_session: ort.InferenceSession | None = None

    @property
    def replay_path(self) -> Path | None:
        """``replay.npz`` when the bundle lists one, else None."""
        return self.path / REPLAY_FILE if REPLAY_FILE in self.manifest.files else None

    def with_session(self, spec: SessionSpec) -> Bundle:
        """The same bundle with a new session built from ``spec``."""
        sess = _session(self.model, spec, str(self.path / MODEL_FILE))
        prep = (
            _session(self.prepare_model, spec, str(self.path / PREPARE_FILE))
            if self.prepare_session is not None
            else None
        )
        return replace(self, session=sess, session_spec=spec, prepare_session=prep)

    def card(self) -> str | None:
        """The model card's text (``MODEL_CARD.md``), or None when the bundle has none.

        The file is checked against its sha256 in ``files`` again as it is read.

        Raises
        ------
        BundleError
            The card changed since the bundle was loaded, is too large or is not UTF-8.
        """
        digest = self.manifest.files.get(CARD_FILE)
        if digest is None:
            return None
        fpath = self.path / CARD_FILE
        try:
            size = fpath.stat().st_size
            if size > MAX_CARD_BYTES:
                raise BundleError(
                    str(fpath), None, f"is {size} bytes; at most {MAX_CARD_BYTES}"
                )
            data = fpath.read_bytes()
        except OSError as exc:
            raise BundleError(
                str(fpath), None, f"cannot be read: {exc.strerror or exc}"
            ) from None
        if sha256_bytes(data) != digest:
            raise BundleError(
                str(fpath),
                None,
                f"sha256 does not match {MANIFEST_FILE} field 'files.{CARD_FILE}': "
                "the card changed after the bundle was written; re-export it",
            )
        try:
            return data.decode("utf-8")
        except UnicodeDecodeError as exc:
            raise BundleError(
                str(fpath), None, f"is not UTF-8 text (byte {exc.start})"
            ) from None


def _one_line(exc: BaseException) -> str:
    """An exception's message on one line (onnxruntime's span several)."""
    return " ".join(str(exc).split()) or type(exc).__name__


def _session(model: bytes, spec: SessionSpec, model_file: str) -> ort.InferenceSession:
    """:func:`make_session`, with onnxruntime's own errors as a BundleError."""
    try:
        return make_session(model, spec)
    except ORT_ERRORS as exc:
        raise BundleError(
            model_file, None, f"onnxruntime refused it: {_one_line(exc)}"
        ) from None


def run_with_deadline(
    session: ort.InferenceSession,
    outputs: list[str] | None,
    feed: dict[str, Any],
    deadline_s: float,
    model_file: str,
) -> list[Any]:
    """One ``session.run`` that is stopped after ``deadline_s`` seconds.

    A timer thread sets onnxruntime's ``RunOptions.terminate`` flag at the deadline,
    which makes the running call (a Loop node included) return with an error; no
    thread is left behind. Used for the graph's first call when a bundle loads, so
    a graph that would run for hours (a Loop of 1e12 iterations) is refused instead.

    Raises
    ------
    BundleError
        Naming ``model_file``: the call did not end in time, or onnxruntime raised.
    """
    options = ort.RunOptions()
    options.log_severity_level = 4  # the error is raised and reported by us
    timer = threading.Timer(deadline_s, setattr, (options, "terminate", True))
    timer.daemon = True
    timer.start()
    try:
        return list(session.run(outputs, feed, options))
    except ORT_ERRORS as exc:
        if options.terminate:
            raise BundleError(
                model_file,
                None,
                f"onnxruntime did not finish the graph's first call within the "
                f"{deadline_s:g} s load deadline (a graph that never ends, such as a "
                "Loop of 1e12 iterations, or a deadline too short for this machine)",
            ) from None
        raise BundleError(
            model_file, None, f"onnxruntime refused it: {_one_line(exc)}"
        ) from None
    finally:
        timer.cancel()


def _varint(data: bytes, pos: int) -> tuple[int, int]:
    """A protobuf varint at ``pos``: (value, position after it)."""
    value = shift = 0
    while True:
        if pos >= len(data) or shift > 63:
            raise ValueError("a varint runs past the end")
        byte = data[pos]
        pos += 1
        value |= (byte & 0x7F) << shift
        shift += 7
        if byte < 0x80:
            return value, pos


def _proto_fields(data: bytes) -> list[tuple[int, int | bytes]]:
    """The top-level fields of a protobuf message: (field number, varint or bytes).

    Fixed-width fields are skipped; groups (wire types 3, 4) are refused.
    """
    out: list[tuple[int, int | bytes]] = []
    pos = 0
    while pos < len(data):
        key, pos = _varint(data, pos)
        number, wire = key >> 3, key & 7
        if wire == 0:
            value, pos = _varint(data, pos)
            out.append((number, value))
        elif wire == 2:
            size, pos = _varint(data, pos)
            if pos + size > len(data):
                raise ValueError("a field runs past the end")
            out.append((number, data[pos : pos + size]))
            pos += size
        elif wire in (1, 5):
            pos += 8 if wire == 1 else 4
        else:
            raise ValueError(f"wire type {wire} is not read here")
    return out


def onnx_opsets(model: bytes) -> dict[str, int]:
    """A serialised ONNX model's ``opset_import``: domain -> version (the highest
    when a domain is listed twice; the default domain is ``""``, ``ai.onnx`` too).

    Read from the protobuf wire format by hand: the gripper PC has no ``onnx``
    package and onnxruntime does not expose a model's opsets. ``ModelProto`` field
    8 is ``opset_import``; ``OperatorSetIdProto`` holds ``domain`` (1) and
    ``version`` (2).

    Raises
    ------
    ValueError
        The bytes are not a well-formed protobuf message.
    """
    opsets: dict[str, int] = {}
    for number, value in _proto_fields(model):
        if number != 8 or not isinstance(value, bytes):
            continue
        domain, version = "", 0
        for sub, item in _proto_fields(value):
            if sub == 1 and isinstance(item, bytes):
                domain = item.decode("utf-8", "replace")
            elif sub == 2 and isinstance(item, int):
                version = item
        domain = "" if domain == "ai.onnx" else domain
        opsets[domain] = max(opsets.get(domain, 0), version)
    return opsets


def _check_opset(
    manifest: Manifest, model: bytes, model_file: str, manifest_file: str
) -> None:
    """The manifest's ``opset`` is the graph's default-domain ``opset_import``."""
    top = Fields(manifest_file, manifest.raw)
    try:
        graph = onnx_opsets(model).get("")
    except ValueError as exc:
        raise BundleError(
            model_file,
            None,
            f"its opset_import cannot be read: {exc}",
        ) from None
    if graph != manifest.opset:
        raise top.error(
            "opset",
            f"is {manifest.opset} but {MODEL_FILE} imports "
            + (
                "no default-domain opset"
                if graph is None
                else f"default-domain opset {graph}"
            )
            + " (opset_import); re-export the bundle",
        )


def _check_graph(
    manifest: Manifest,
    session: ort.InferenceSession,
    model_file: str,
    manifest_file: str,
) -> None:
    top = Fields(manifest_file, manifest.raw)
    (want,) = manifest.inputs
    graph_inputs = session.get_inputs()
    if manifest.state:
        _check_state(manifest, session, top)
        state_inputs = {s.input for s in manifest.state}
        graph_inputs = [g for g in graph_inputs if g.name not in state_inputs]
    if manifest.prepare is not None:
        if manifest.prepare not in {g.name for g in graph_inputs}:
            raise top.error(
                "prepare.tensor",
                f"{manifest.prepare!r} is not an input of {MODEL_FILE}; its inputs are "
                f"{sorted(g.name for g in graph_inputs)}",
            )
        graph_inputs = [g for g in graph_inputs if g.name != manifest.prepare]
    if len(graph_inputs) != 1:
        raise BundleError(
            model_file,
            None,
            f"the graph has {len(graph_inputs)} inputs besides the state or the "
            "prepared tensor; the runtime feeds exactly one"
            if manifest.state or manifest.prepare
            else f"the graph has {len(graph_inputs)} inputs; the runtime feeds exactly one",
        )
    got = graph_inputs[0]
    if got.name != want.name:
        raise top.error(
            "inputs[0].name", f"is {want.name!r} but the graph's input is {got.name!r}"
        )
    if INPUT_DTYPES.get(got.type) != want.dtype:
        raise top.error(
            "inputs[0].dtype", f"is {want.dtype!r} but the graph's input is {got.type}"
        )
    assert want.shape is not None
    static = [d if isinstance(d, int) else None for d in got.shape]
    if len(static) != len(want.shape) or any(
        g is not None and g != w for g, w in zip(static, want.shape, strict=False)
    ):
        raise top.error(
            "inputs[0].shape",
            f"is {list(want.shape)} but the graph's input has shape {got.shape}",
        )
    graph_outputs = {o.name: o for o in session.get_outputs()}
    for i, out in enumerate(manifest.outputs):
        if out.name not in graph_outputs:
            raise top.error(
                f"outputs[{i}].name",
                f"{out.name!r} is not a graph output; the graph has {sorted(graph_outputs)}",
            )
        g = graph_outputs[out.name]
        if out.dtype is not None and onnx_dtype(g.type) != out.dtype:
            raise top.error(
                f"outputs[{i}].dtype",
                f"is {out.dtype!r} but the graph's output {out.name!r} is {g.type}",
            )
        if out.shape is not None:
            gdims = [d if isinstance(d, int) else None for d in (g.shape or [])]
            if len(gdims) != len(out.shape) or any(
                a is not None and b is not None and a != b
                for a, b in zip(gdims, out.shape, strict=False)
            ):
                raise top.error(
                    f"outputs[{i}].shape",
                    f"is {list(out.shape)} but the graph's output {out.name!r} has "
                    f"shape {g.shape}",
                )
    score = graph_outputs[manifest.decision.output]
    if score.type not in SCORE_DTYPES:
        raise top.error(
            "decision.output",
            f"{score.name!r} has type {score.type}; a score must be float or double",
        )


def _check_state(
    manifest: Manifest, session: ort.InferenceSession, top: Fields
) -> None:
    """Each ``state`` entry names a graph input and output of its shape and dtype."""
    ins = {g.name: g for g in session.get_inputs()}
    outs = {g.name: g for g in session.get_outputs()}
    for i, s in enumerate(manifest.state):
        for key, graph in (("input", ins), ("output", outs)):
            name = getattr(s, key)
            if name not in graph:
                raise top.error(
                    f"state[{i}].{key}",
                    f"{name!r} is not a graph {key}; the graph has {sorted(graph)}",
                )
            g = graph[name]
            if onnx_dtype(g.type) != s.dtype:
                raise top.error(
                    f"state[{i}].dtype",
                    f"is {s.dtype!r} but the graph's {key} {name!r} is {g.type}",
                )
            dims = list(g.shape or [])
            if len(dims) != len(s.shape) or any(
                isinstance(d, int) and d != w
                for d, w in zip(dims, s.shape, strict=False)
            ):
                raise top.error(
                    f"state[{i}].shape",
                    f"is {list(s.shape)} but the graph's {key} {name!r} has shape {dims}",
                )


def _check_decision_size(
    manifest: Manifest,
    session: ort.InferenceSession,
    manifest_file: str,
    model_file: str,
    deadline_s: float,
    prepared: Mapping[str, Any] | None = None,
) -> None:
    """One call on a zero input, under the deadline: the score output must have the
    shape the manifest gives and the entries the rule reads (``prepared``: the
    prepare graph's output on the same zero input, fed too)."""
    (inp,) = manifest.inputs
    x = np.zeros(inp.static_shape, dtype=np.dtype(inp.dtype))
    feed = {inp.name: x, **(prepared or {})}
    feed.update(
        {s.input: np.zeros(s.shape, dtype=np.dtype(s.dtype)) for s in manifest.state}
    )
    score, *states = run_with_deadline(
        session,
        [manifest.decision.output, *(s.output for s in manifest.state)],
        feed,
        deadline_s,
        model_file,
    )
    score = np.asarray(score)
    size = int(score.size)
    top = Fields(manifest_file, manifest.raw)
    for i, (s, h) in enumerate(zip(manifest.state, states, strict=True)):
        if tuple(np.shape(h)) != s.shape:
            raise top.error(
                f"state[{i}].shape",
                f"is {list(s.shape)} but the graph's first call gave output "
                f"{s.output!r} of shape {list(np.shape(h))}",
            )
    d = manifest.decision
    for i, out in enumerate(manifest.outputs):
        if (
            out.name == d.output
            and out.shape is not None
            and (
                len(out.shape) != score.ndim
                or any(
                    w is not None and w != g
                    for w, g in zip(out.shape, score.shape, strict=False)
                )
            )
        ):
            raise top.error(
                f"outputs[{i}].shape",
                f"is {list(out.shape)} but the graph's first call gave "
                f"{list(score.shape)}",
            )
    if d.rule == "argmax" and d.classes is not None and size != len(d.classes):
        raise top.error(
            "decision.classes",
            f"names {len(d.classes)} classes but output {d.output!r} has {size} entries per frame",
        )
    if d.rule == "threshold" and d.column >= size:
        raise top.error(
            "decision.column",
            f"is {d.column} but output {d.output!r} has {size} entries per frame",
        )


def _read_manifest(manifest_path: Path) -> tuple[Any, bytes]:
    """The decoded manifest.json and its bytes: size-capped, strict JSON (no NaN),
    depth-capped."""
    mfile = str(manifest_path)
    try:
        size = manifest_path.stat().st_size
        if size > MAX_MANIFEST_BYTES:
            raise BundleError(
                mfile, None, f"is {size} bytes; at most {MAX_MANIFEST_BYTES} are read"
            )
        data = manifest_path.read_bytes()
    except OSError as exc:
        raise BundleError(
            mfile, None, f"cannot be read: {exc.strerror or exc}"
        ) from None

    try:
        # NaN / Infinity are parsed here and refused by validate_manifest, which can
        # name the field that holds them.
        obj = json.loads(data.decode("utf-8"))
    except RecursionError:
        raise BundleError(
            mfile,
            None,
            f"is not valid JSON: nested deeper than {MAX_JSON_DEPTH} levels",
        ) from None
    except (UnicodeDecodeError, ValueError) as exc:  # JSONDecodeError is a ValueError
        raise BundleError(mfile, None, f"is not valid JSON: {_one_line(exc)}") from None
    depth = json_depth(obj)
    if depth > MAX_JSON_DEPTH:
        raise BundleError(
            mfile, None, f"is nested {depth} levels deep; at most {MAX_JSON_DEPTH}"
        )
    return obj, data


def _check_digest(obj: Any, mfile: str) -> None:
    """Compare ``manifest_sha256`` with the manifest's content (this schema version only:
    an older or foreign manifest is named by :func:`validate_manifest` instead)."""
    if not (
        isinstance(obj, dict)
        and obj.get("format") == FORMAT
        and obj.get("schema_version") in READ_VERSIONS
    ):
        return
    top = Fields(mfile, obj)
    given = top.string(DIGEST_FIELD)
    actual = manifest_digest(obj)
    if given != actual:
        raise top.error(
            DIGEST_FIELD,
            f"is {given[:16]}... but the manifest's content has sha256 {actual[:16]}...: "
            "manifest.json was edited or damaged after the bundle was written; "
            "re-export it",
        )


def load_bundle(
    path: str | Path,
    *,
    session: SessionSpec | None = None,
    deadline_s: float = DEFAULT_DEADLINE_S,
    key: bytes | None = None,
) -> Bundle:
    """Load and check a bundle folder, then build its onnxruntime session.

    Order of checks: the folder and ``manifest.json`` exist; the manifest is strict
    JSON of bounded size and depth, its ``manifest_sha256`` matches its content, and
    it matches schema version 2 or 3 (types, bounds, cross-field rules); every file in
    ``files`` exists and has the listed sha256 (``model.onnx`` always); only then is
    the graph given to onnxruntime; its input/output names, dtypes and static
    shapes must match the manifest, the preprocessing must produce exactly the
    input's number of values, and the graph's first call (on a zero input, stopped
    after ``deadline_s``) must give the score shape and entries the decision rule
    reads. onnxruntime's own errors become a :class:`BundleError` naming
    ``model.onnx``.

    Parameters
    ----------
    path : str or Path
        The bundle folder (``exports/<name>``).
    session : SessionSpec, optional
        Session options to use instead of the manifest's (for tuning).
    deadline_s : float
        Seconds the graph's first call may take (default 5; in (0, 3600]).
    key : bytes, optional
        The lab's signing key (:func:`read_key`): the bundle must then hold
        ``manifest.hmac``, the HMAC-SHA256 of ``manifest.json``'s bytes under it,
        checked before anything else in the manifest is read. Without a key
        ``manifest.hmac`` is not read.

    Returns
    -------
    Bundle

    Raises
    ------
    BundleError
        Naming the file and, for manifest problems, the field.
    """
    root = Path(path)
    recover_leftovers(root)  # an interrupted overwrite: restore or report it
    manifest_path = root / MANIFEST_FILE
    mfile = str(manifest_path)
    if not root.is_dir():
        raise BundleError(
            str(root),
            None,
            "is not a bundle folder (expected a folder with model.onnx and manifest.json)",
        )
    if not manifest_path.is_file():
        raise BundleError(mfile, None, "is missing: every bundle has a manifest.json")
    if not (isinstance(deadline_s, int | float) and 0 < deadline_s <= MAX_DEADLINE_S):
        raise BundleError(
            str(root / MODEL_FILE),
            None,
            f"load deadline must be in (0, {MAX_DEADLINE_S:g}] s; got {deadline_s!r}",
        )
    obj, manifest_bytes = _read_manifest(manifest_path)
    if key is not None:
        _check_hmac(root, manifest_bytes, key)
    _check_digest(obj, mfile)
    manifest = validate_manifest(obj, mfile)
    model = prepare_model = b""
    for fname, digest in manifest.files.items():
        fpath = root / fname
        if not fpath.is_file():
            raise BundleError(
                str(fpath),
                None,
                f"is missing but listed in {MANIFEST_FILE} field 'files.{fname}'",
            )
        try:
            if fname in (MODEL_FILE, PREPARE_FILE):
                size = fpath.stat().st_size
                if size > MAX_MODEL_BYTES:
                    raise BundleError(
                        str(fpath), None, f"is {size} bytes; at most {MAX_MODEL_BYTES}"
                    )
                content = fpath.read_bytes()
                actual = sha256_bytes(content)
                if fname == MODEL_FILE:
                    model = content
                else:
                    prepare_model = content
            else:
                actual = sha256_file(fpath)
        except OSError as exc:
            raise BundleError(
                str(fpath), None, f"cannot be read: {exc.strerror or exc}"
            ) from None
        if actual != digest:
            raise BundleError(
                str(fpath),
                None,
                f"sha256 {actual} does not match {MANIFEST_FILE} field 'files.{fname}' "
                f"({digest}): the file changed after the bundle was written; re-export it",
            )
    spec = manifest.session if session is None else session
    model_file = str(root / MODEL_FILE)
    sess = _session(model, spec, model_file)
    _check_opset(manifest, model, model_file, mfile)
    _check_graph(manifest, sess, model_file, mfile)
    window_shape = (manifest.frame.window, *manifest.frame.shape)
    pipeline = Pipeline(manifest.preprocessing, window_shape, mfile)
    (inp,) = manifest.inputs
    in_shape = inp.static_shape
    if math.prod(pipeline.out_shape) != math.prod(in_shape):
        raise BundleError(
            mfile,
            "inputs[0].shape",
            f"{list(in_shape)} holds {math.prod(in_shape)} values but the window "
            f"{list(window_shape)} after preprocessing has shape {list(pipeline.out_shape)}",
        )
    prep_sess = None
    prepared: dict[str, Any] = {}
    if manifest.prepare is not None:
        prep_file = str(root / PREPARE_FILE)
        prep_sess = _session(prepare_model, spec, prep_file)
        prepared = _check_prepare(
            manifest, prep_sess, sess, prep_file, mfile, deadline_s
        )
    _check_decision_size(manifest, sess, mfile, model_file, float(deadline_s), prepared)
    return Bundle(
        root,
        manifest,
        model,
        sess,
        spec,
        pipeline,
        float(deadline_s),
        prepare_model,
        prep_sess,
    )


def _check_prepare(
    manifest: Manifest,
    prep: ort.InferenceSession,
    main: ort.InferenceSession,
    prep_file: str,
    manifest_file: str,
    deadline_s: float,
) -> dict[str, Any]:
    """``prepare.onnx`` reads ``inputs[0]`` and gives ``prepare.tensor`` as the main
    graph takes it; its first call (zero input, under the deadline) gives the feed
    for the main graph's first call."""
    (want,) = manifest.inputs
    ins = prep.get_inputs()
    if len(ins) != 1 or ins[0].name != want.name:
        raise BundleError(
            prep_file,
            None,
            f"must have one input named {want.name!r} (inputs[0]); it has "
            f"{[g.name for g in ins]}",
        )
    if INPUT_DTYPES.get(ins[0].type) != want.dtype:
        raise BundleError(
            prep_file,
            None,
            f"input {want.name!r} is {ins[0].type} but inputs[0].dtype is {want.dtype!r}",
        )
    assert want.shape is not None
    dims = [d if isinstance(d, int) else None for d in (ins[0].shape or [])]
    if len(dims) != len(want.shape) or any(
        d is not None and d != w for d, w in zip(dims, want.shape, strict=False)
    ):
        raise BundleError(
            prep_file,
            None,
            f"input {want.name!r} has shape {ins[0].shape} but inputs[0].shape is "
            f"{list(want.shape)} (the loop feeds both graphs the same window)",
        )
    tensor = manifest.prepare
    assert tensor is not None  # only called for a bundle with a prepare graph
    outs = {o.name: o for o in prep.get_outputs()}
    if tensor not in outs:
        raise BundleError(
            prep_file,
            None,
            f"has no output {tensor!r} (manifest field 'prepare.tensor'); its outputs "
            f"are {sorted(outs)}",
        )
    feed_in = {g.name: g for g in main.get_inputs()}[tensor]
    if outs[tensor].type != feed_in.type:
        raise BundleError(
            prep_file,
            None,
            f"output {tensor!r} is {outs[tensor].type} but {MODEL_FILE} reads it as "
            f"{feed_in.type}",
        )
    x = np.zeros(want.static_shape, dtype=np.dtype(want.dtype))
    (value,) = run_with_deadline(prep, [tensor], {want.name: x}, deadline_s, prep_file)
    value = np.asarray(value)
    dims = list(feed_in.shape or [])
    if len(dims) != value.ndim or any(
        isinstance(d, int) and d != v for d, v in zip(dims, value.shape, strict=False)
    ):
        raise BundleError(
            prep_file,
            None,
            f"output {tensor!r} has shape {list(value.shape)} on the first call but "
            f"{MODEL_FILE} reads it as {dims}",
        )
    return {tensor: value}


def _jsonable(value: Any) -> Any:
    """``json.dumps`` default: numpy arrays and scalars become lists and numbers."""
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    raise TypeError(f"{type(value).__name__} is not JSON serialisable")


def _describe_outputs(outputs: Any, model: bytes, model_file: str) -> Any:
    """The manifest's ``outputs`` with each one's dtype and shape filled in from the graph.

    Entries that are not ``{name: ...}`` objects, or name no graph output, are left
    as they are for :func:`validate_manifest` and :func:`load_bundle` to name.
    """
    if not isinstance(outputs, list):
        return outputs
    graph = {
        o.name: o for o in _session(model, SessionSpec(), model_file).get_outputs()
    }
    out = []
    for item in outputs:
        if isinstance(item, Mapping) and item.get("name") in graph:
            g = graph[item["name"]]
            item = dict(item)
            item.setdefault("dtype", onnx_dtype(g.type))
            if g.shape is not None and "shape" not in item:
                item["shape"] = [
                    d if isinstance(d, int) and d > 0 else None for d in g.shape
                ]
        out.append(item)
    return out


def write_bundle(
    out: str | Path,
    model: bytes,
    manifest: Mapping[str, Any],
    *,
    replay: tuple[np.ndarray, np.ndarray] | None = None,
    overwrite: bool = False,
    prepare: bytes | None = None,
    key: bytes | None = None,
    card: str | None = None,
) -> Path:
    """Write a bundle atomically: a temporary sibling folder, checked, then renamed.

    Parameters
    ----------
    out : str or Path
        The bundle folder to create (``exports/<name>``).
    model : bytes
        The serialised ONNX graph (``model.SerializeToString()``).
    manifest : mapping
        The manifest without ``files`` and ``manifest_sha256`` (computed here);
        ``format`` and ``schema_version`` are filled in when absent, and so are
        each listed output's ``dtype`` and ``shape`` (read from the graph; a
        symbolic dimension is ``null``). numpy arrays and scalars are written as
        JSON lists and numbers.
    replay : (frames, timestamps), optional
        Recorded frames ``(n, *frame.shape)`` and their times ``(n,)`` in s, written
        as ``replay.npz`` for ``slipkit-run <bundle>`` and session tuning.
    overwrite : bool
        Replace an existing bundle folder (only a bundle: any other folder or file
        under out is refused, as is an out inside a slipkit folder).
    prepare : bytes, optional
        The prepare graph (``prepare.onnx``; the manifest then has ``prepare``).
    key : bytes, optional
        Sign the bundle: ``manifest.hmac`` holds :func:`manifest_hmac` of the
        written ``manifest.json`` under this key.
    card : str, optional
        The model card, written as ``MODEL_CARD.md`` (:data:`CARD_FILE`) and listed
        in ``files`` like the graph.

    Returns
    -------
    Path
        ``out``.

    Raises
    ------
    BundleError
        When the written bundle does not load (:func:`load_bundle` runs on the
        temporary folder first, so a bad bundle is never left under ``out``).
    """
    # Deferred import: sources imports this module for REPLAY_FILE.
    from slipkit.runtime.sources import check_replay_arrays

    target = Path(out)
    mfile = str(target / MANIFEST_FILE)
    if target.exists() and not overwrite:
        raise BundleError(
            str(target), None, "already exists (pass overwrite=True to replace it)"
        )
    man = dict(manifest)
    man.setdefault("format", FORMAT)
    man.setdefault("schema_version", SCHEMA_VERSION)
    man["files"] = {MODEL_FILE: sha256_bytes(model)}
    if prepare is not None:
        man["files"][PREPARE_FILE] = sha256_bytes(prepare)
    man.pop(DIGEST_FIELD, None)
    man["outputs"] = _describe_outputs(
        man.get("outputs"), model, str(target / MODEL_FILE)
    )
    try:
        # A JSON round trip first: the manifest is checked exactly as it will be read.
        man = json.loads(json.dumps(man, default=_jsonable, allow_nan=False))
    except (TypeError, ValueError) as exc:
        raise BundleError(
            mfile, None, f"cannot be written as strict JSON: {exc}"
        ) from None
    checked = validate_manifest(man, mfile)
    with atomic_dir(target, overwrite=overwrite, kind="bundle") as tmp:
        (tmp / MODEL_FILE).write_bytes(model)
        if prepare is not None:
            (tmp / PREPARE_FILE).write_bytes(prepare)
        if replay is not None:
            frames, times = check_replay_arrays(
                np.asarray(replay[0]),
                np.asarray(replay[1]),
                checked.frame.shape,
                str(target / REPLAY_FILE),
            )
            np.savez(tmp / REPLAY_FILE, frames=frames, timestamps=times)
            man["files"][REPLAY_FILE] = sha256_file(tmp / REPLAY_FILE)
        if card is not None:
            data = card.encode("utf-8")
            (tmp / CARD_FILE).write_bytes(data)
            man["files"][CARD_FILE] = sha256_bytes(data)
        # The digest last, over the final content (files included).
        man = sign_manifest(man)
        text = json.dumps(man, indent=2) + "\n"
        (tmp / MANIFEST_FILE).write_text(text, encoding="utf-8")
        if key is not None:
            data = (tmp / MANIFEST_FILE).read_bytes()
            (tmp / SIGNATURE_FILE).write_text(manifest_hmac(data, key) + "\n")
        # the graph, its IO, the preprocessing and the signature, before the rename
        load_bundle(tmp, key=key)
    return target
