"""The bundle format: ``exports/<name>/`` = ``model.onnx`` + ``manifest.json`` (+ ``replay.npz``).

A bundle is everything a gripper PC needs to decide slip from raw sensor frames: the
ONNX graph, the numpy preprocessing the graph does not hold (a closed registry of
named ops, :mod:`slipkit.runtime.preprocessing`), the decision rule, the debounce, the
latency budget and the session options. Loading never executes code from the bundle
(JSON and ONNX only; no pickle anywhere) and checks the manifest's types and the
sha256 of every listed file before an onnxruntime session is created.

Manifest schema, version 1 (every field is described in ``docs/deploy.md``)::

    {
      "format": "slipkit-bundle", "schema_version": 1, "name": "tactip_svm",
      "description": "optional free text",
      "frame": {"streams": ["pins"], "channels": ["x0", ..., "y126"], "shape": [254],
                "window": 2, "hop": 1, "rate_hz": 120.0},
      "preprocessing": [{"op": "pin_velocity_features", "variant": "dr_dtheta"},
                        {"op": "standardize", "mean": [...], "scale": [...]}],
      "inputs": [{"name": "X", "dtype": "float32", "shape": [1, 254]}],
      "outputs": [{"name": "label"}, {"name": "score", "dtype": "float32"}],
      "decision": {"output": "score", "rule": "threshold", "column": 0,
                   "classes": ["static", "slip"], "positive": "slip",
                   "strict": false},
      "threshold": 0.0,
      "debounce": {"k": 2},
      "budget_ms": {"frame_period": 8.333, "p99": 0.833},
      "session": {"intra_op_num_threads": 1, "inter_op_num_threads": 1,
                  "graph_optimization_level": "all", "allow_spinning": false,
                  "warmup": 20},
      "opset": 17,
      "producer": {"slipkit": "0.1.0", "onnx": "1.23.2", "skl2onnx": "1.19.1"},
      "training": {"data_fingerprint": "…", "metrics": {"test": {"f1": 0.97}}},
      "files": {"model.onnx": "<sha256 hex>", "replay.npz": "<sha256 hex>"}
    }
"""

from __future__ import annotations

import json
import math
import re
from collections.abc import Mapping
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
import onnxruntime as ort

from slipkit._files import atomic_dir, recover_leftovers, sha256_bytes, sha256_file
from slipkit.runtime._schema import Fields
from slipkit.runtime.errors import BundleError
from slipkit.runtime.preprocessing import Pipeline
from slipkit.runtime.session import SessionSpec, make_session

FORMAT = "slipkit-bundle"
SCHEMA_VERSION = 1
MODEL_FILE = "model.onnx"
MANIFEST_FILE = "manifest.json"
#: Recorded frames an exporter may add for ``slipkit-run <bundle>`` and session tuning.
REPLAY_FILE = "replay.npz"

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
)
#: Graph input dtypes the loop can feed (ONNX type string -> manifest name).
INPUT_DTYPES = {"tensor(float)": "float32", "tensor(double)": "float64"}
#: ONNX type strings of outputs the decision can read.
SCORE_DTYPES = {"tensor(float)": "float32", "tensor(double)": "float64"}
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
    """A graph input or output: name, dtype (``float32``...) and shape (None: unchecked)."""

    name: str
    dtype: str | None
    shape: tuple[int, ...] | None


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
    """

    output: str
    rule: str
    column: int
    classes: tuple[str, ...] | None
    positive: str | None
    threshold: float | None
    strict: bool = False

    @property
    def slip_above(self) -> bool:
        """Whether a score at or above the threshold means slip (threshold rule)."""
        return self.classes is None or self.positive == self.classes[1]


@dataclass(frozen=True)
class Budget:
    """Latency budget per decision, ms: the sensor's frame period and the p99 target."""

    frame_period_ms: float
    p99_ms: float


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


def _tensors(top: Fields, key: str, *, need_shape: bool) -> tuple[TensorSpec, ...]:
    value = top.raw(key)
    if not isinstance(value, list) or not value:
        raise top.error(key, "must be a non-empty list of {name, dtype, shape} objects")
    specs = []
    for i, item in enumerate(value):
        f = Fields(top.file, item, f"{key}[{i}]")
        f.only(("name", "dtype", "shape"))
        dtype = f.raw("dtype", None)
        if dtype is not None:
            dtype = f.string("dtype")
        shape = f.integers("shape") if need_shape or "shape" in f.obj else None
        specs.append(TensorSpec(f.string("name"), dtype, shape))
    names = [s.name for s in specs]
    if len(set(names)) != len(names):
        raise top.error(key, f"names must be unique; got {names}")
    return tuple(specs)


def _frame(f: Fields) -> FrameSpec:
    f.only(("streams", "channels", "shape", "window", "hop", "rate_hz"))
    spec = FrameSpec(
        streams=f.strings("streams"),
        channels=f.strings("channels", unique=True),
        shape=f.integers("shape"),
        window=f.integer("window", minimum=1),
        hop=f.integer("hop", 1, minimum=1),
        rate_hz=f.number("rate_hz", positive=True),
    )
    if spec.n_values != len(spec.channels):
        raise f.error(
            "channels",
            f"has {len(spec.channels)} names but frame.shape {list(spec.shape)} holds "
            f"{spec.n_values} values (one name per value)",
        )
    return spec


def _decision(top: Fields, outputs: tuple[TensorSpec, ...]) -> DecisionSpec:
    f = top.child("decision")
    f.only(("output", "rule", "column", "classes", "positive", "strict"))
    names = [o.name for o in outputs]
    output = f.string("output", choices=names)
    rule = f.string("rule", choices=("threshold", "argmax"))
    classes = f.strings("classes", unique=True) if "classes" in f.obj else None
    positive = None
    if classes is not None:
        positive = f.string("positive", choices=classes)
    elif "positive" in f.obj:
        raise f.error("positive", "needs decision.classes to name the classes")
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
        if top.raw("threshold", None) is not None:
            raise top.error("threshold", "must be null or absent for the argmax rule")
        threshold = None
        if "strict" in f.obj:
            raise f.error("strict", "is not used by the argmax rule")
    else:
        column = f.integer("column", 0, minimum=0)
        if classes is not None and len(classes) != 2:
            raise f.error(
                "classes",
                f"the threshold rule has two classes (negative, positive); got {list(classes)}",
            )
        threshold = top.number("threshold")
    strict = f.boolean("strict", False)
    return DecisionSpec(output, rule, column, classes, positive, threshold, strict)


def validate_manifest(obj: object, file: str = MANIFEST_FILE) -> Manifest:
    """Check a decoded manifest against schema version 1.

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
    """
    top = Fields(file, obj)
    fmt = top.raw("format")
    if fmt != FORMAT:
        raise top.error(
            "format", f"must be {FORMAT!r}; got {fmt!r} (not a slipkit bundle)"
        )
    version = top.integer("schema_version")
    if version != SCHEMA_VERSION:
        raise top.error(
            "schema_version",
            f"this runtime reads version {SCHEMA_VERSION}; got {version} "
            "(install the slipkit version that wrote the bundle)",
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
    decision = _decision(top, outputs)
    deb = top.child("debounce")
    deb.only(("k",))
    budget_f = top.child("budget_ms")
    budget_f.only(("frame_period", "p99"))
    budget = Budget(
        budget_f.number("frame_period", positive=True),
        budget_f.number("p99", positive=True),
    )
    if budget.p99_ms > budget.frame_period_ms:
        raise budget_f.error(
            "p99",
            f"must not exceed the frame period ({budget.frame_period_ms} ms); got {budget.p99_ms}",
        )
    session = SessionSpec.from_fields(top.child("session", {}))
    opset = top.integer("opset", minimum=1)
    prod = top.child("producer")
    producer = {k: prod.string(k) for k in prod.obj}
    training = top.child("training", {})
    if "data_fingerprint" in training.obj:
        training.string("data_fingerprint")
    if "metrics" in training.obj:
        training.child("metrics")
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
    return Manifest(
        name=name,
        frame=frame,
        preprocessing=tuple(steps),
        inputs=inputs,
        outputs=outputs,
        decision=decision,
        debounce_k=deb.integer("k", minimum=1),
        budget=budget,
        session=session,
        opset=opset,
        producer=producer,
        training=dict(training.obj),
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
    """

    path: Path
    manifest: Manifest
    model: bytes
    session: ort.InferenceSession
    session_spec: SessionSpec
    preprocessing: Pipeline

    @property
    def replay_path(self) -> Path | None:
        """``replay.npz`` when the bundle lists one, else None."""
        return self.path / REPLAY_FILE if REPLAY_FILE in self.manifest.files else None

    def with_session(self, spec: SessionSpec) -> Bundle:
        """The same bundle with a new session built from ``spec``."""
        return replace(self, session=make_session(self.model, spec), session_spec=spec)


def _check_graph(
    manifest: Manifest,
    session: ort.InferenceSession,
    model_file: str,
    manifest_file: str,
) -> None:
    top = Fields(manifest_file, manifest.raw)
    (want,) = manifest.inputs
    graph_inputs = session.get_inputs()
    if len(graph_inputs) != 1:
        raise BundleError(
            model_file,
            None,
            f"the graph has {len(graph_inputs)} inputs; the runtime feeds exactly one",
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
    score = graph_outputs[manifest.decision.output]
    if score.type not in SCORE_DTYPES:
        raise top.error(
            "decision.output",
            f"{score.name!r} has type {score.type}; a score must be float or double",
        )


def _check_decision_size(
    manifest: Manifest, session: ort.InferenceSession, manifest_file: str
) -> None:
    """One call on a zero input: the score output must have the entries the rule reads."""
    (inp,) = manifest.inputs
    assert inp.shape is not None
    x = np.zeros(inp.shape, dtype=np.dtype(inp.dtype))
    (score,) = session.run([manifest.decision.output], {inp.name: x})
    size = int(np.asarray(score).size)
    top = Fields(manifest_file, manifest.raw)
    d = manifest.decision
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


def load_bundle(path: str | Path, *, session: SessionSpec | None = None) -> Bundle:
    """Load and check a bundle folder, then build its onnxruntime session.

    Order of checks: the folder and ``manifest.json`` exist; the manifest is JSON
    and matches schema version 1 (types, ranges, cross-field rules); every file in
    ``files`` exists and has the listed sha256 (``model.onnx`` always); only then is
    the graph given to onnxruntime; its input/output names, dtypes and static
    shapes must match the manifest, the preprocessing must produce exactly the
    input's number of values, and the score output must have the entries the
    decision rule reads.

    Parameters
    ----------
    path : str or Path
        The bundle folder (``exports/<name>``).
    session : SessionSpec, optional
        Session options to use instead of the manifest's (for tuning).

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
    try:
        obj = json.loads(manifest_path.read_text(encoding="utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise BundleError(mfile, None, f"is not valid JSON: {exc}") from None
    manifest = validate_manifest(obj, mfile)
    model = b""
    for fname, digest in manifest.files.items():
        fpath = root / fname
        if not fpath.is_file():
            raise BundleError(
                str(fpath),
                None,
                f"is missing but listed in {MANIFEST_FILE} field 'files.{fname}'",
            )
        if fname == MODEL_FILE:
            model = fpath.read_bytes()
            actual = sha256_bytes(model)
        else:
            actual = sha256_file(fpath)
        if actual != digest:
            raise BundleError(
                str(fpath),
                None,
                f"sha256 {actual} does not match {MANIFEST_FILE} field 'files.{fname}' "
                f"({digest}): the file changed after the bundle was written; re-export it",
            )
    spec = manifest.session if session is None else session
    model_file = str(root / MODEL_FILE)
    try:
        sess = make_session(model, spec)
    except Exception as exc:  # onnxruntime raises its own exception types
        raise BundleError(
            model_file, None, f"onnxruntime cannot load the graph: {exc}"
        ) from None
    _check_graph(manifest, sess, model_file, mfile)
    window_shape = (manifest.frame.window, *manifest.frame.shape)
    pipeline = Pipeline(manifest.preprocessing, window_shape, mfile)
    (inp,) = manifest.inputs
    assert inp.shape is not None
    if math.prod(pipeline.out_shape) != math.prod(inp.shape):
        raise BundleError(
            mfile,
            "inputs[0].shape",
            f"{list(inp.shape)} holds {math.prod(inp.shape)} values but the window "
            f"{list(window_shape)} after preprocessing has shape {list(pipeline.out_shape)}",
        )
    _check_decision_size(manifest, sess, mfile)
    return Bundle(root, manifest, model, sess, spec, pipeline)


def _jsonable(value: Any) -> Any:
    """``json.dumps`` default: numpy arrays and scalars become lists and numbers."""
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    raise TypeError(f"{type(value).__name__} is not JSON serialisable")


def write_bundle(
    out: str | Path,
    model: bytes,
    manifest: Mapping[str, Any],
    *,
    replay: tuple[np.ndarray, np.ndarray] | None = None,
    overwrite: bool = False,
) -> Path:
    """Write a bundle atomically: a temporary sibling folder, checked, then renamed.

    Parameters
    ----------
    out : str or Path
        The bundle folder to create (``exports/<name>``).
    model : bytes
        The serialised ONNX graph (``model.SerializeToString()``).
    manifest : mapping
        The manifest without ``files`` (computed here); ``format`` and
        ``schema_version`` are filled in when absent. numpy arrays and scalars
        are written as JSON lists and numbers.
    replay : (frames, timestamps), optional
        Recorded frames ``(n, *frame.shape)`` and their times ``(n,)`` in s, written
        as ``replay.npz`` for ``slipkit-run <bundle>`` and session tuning.
    overwrite : bool
        Replace an existing bundle folder (only a bundle: any other folder or file
        under ``out`` is refused, as is an ``out`` inside a slipkit folder).

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
        if replay is not None:
            frames, times = check_replay_arrays(
                np.asarray(replay[0]),
                np.asarray(replay[1]),
                checked.frame.shape,
                str(target / REPLAY_FILE),
            )
            np.savez(tmp / REPLAY_FILE, frames=frames, timestamps=times)
            man["files"][REPLAY_FILE] = sha256_file(tmp / REPLAY_FILE)
        text = json.dumps(man, indent=2) + "\n"
        (tmp / MANIFEST_FILE).write_text(text, encoding="utf-8")
        load_bundle(tmp)  # the graph, its IO and the preprocessing, before the rename
    return target
