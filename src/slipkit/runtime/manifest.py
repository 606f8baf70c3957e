"""The bundle manifest: format constants, the field specs, the checked reader
(:func:`validate_manifest`), its digest and the optional HMAC signature.

The format itself is described in :mod:`slipkit.runtime.bundle`.
"""

from __future__ import annotations

import hashlib
import hmac
import json
import math
import re
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from slipkit._files import sha256_bytes
from slipkit.runtime._schema import (
    MAX_DEBOUNCE_K,
    MAX_FRAME_PERIOD_MS,
    MAX_FRAMES,
    MAX_JSON_DEPTH,
    MAX_OPSET,
    MAX_RATE_HZ,
    MAX_VALUES,
    Fields,
    json_depth,
)
from slipkit.runtime.errors import BundleError, OptionError
from slipkit.runtime.session import SessionSpec

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
