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

import json
import math
import threading
from collections.abc import Mapping
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
import onnxruntime as ort

from slipkit._files import recover_leftovers, sha256_bytes, sha256_file
from slipkit.runtime._schema import (
    MAX_JSON_DEPTH,
    MAX_MANIFEST_BYTES,
    MAX_MODEL_BYTES,
    Fields,
    json_depth,
)
from slipkit.runtime.errors import BundleError
from slipkit.runtime.manifest import (
    _FILE_NAME,
    _SHA256,
    BUDGET_SOURCES,
    CARD_FILE,
    DEFAULT_DEADLINE_S,
    DIGEST_FIELD,
    FORMAT,
    INPUT_DTYPES,
    MANIFEST_FILE,
    MAX_CARD_BYTES,
    MAX_DEADLINE_S,
    MAX_KEY_BYTES,
    MAX_STATE,
    MAX_TEXT,
    MODEL_FILE,
    ONNX_DTYPES,
    PREPARE_FILE,
    READ_VERSIONS,
    REPLAY_FILE,
    SCHEMA_VERSION,
    SCORE_DTYPES,
    SIGNATURE_FILE,
    STATE_DTYPES,
    TOP_FIELDS,
    Budget,
    DecisionSpec,
    FrameSpec,
    Manifest,
    StateSpec,
    TensorSpec,
    _check_hmac,
    _decision,
    _first_nonfinite,
    _frame,
    _output_shape,
    _prepare,
    _short_list,
    _slip_columns,
    _state,
    _tensors,
    _text,
    _training,
    manifest_digest,
    manifest_hmac,
    onnx_dtype,
    read_key,
    sign_manifest,
    validate_manifest,
)
from slipkit.runtime.preprocessing import Pipeline
from slipkit.runtime.session import ORT_ERRORS, SessionSpec, make_session


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


# The writer lives in its own module (training side writes, the gripper PC reads).
from slipkit.runtime.bundle_write import (  # noqa: E402
    _describe_outputs,
    _jsonable,
    write_bundle,
)

__all__ = [
    "BUDGET_SOURCES",
    "CARD_FILE",
    "DEFAULT_DEADLINE_S",
    "DIGEST_FIELD",
    "FORMAT",
    "INPUT_DTYPES",
    "MANIFEST_FILE",
    "MAX_CARD_BYTES",
    "MAX_DEADLINE_S",
    "MAX_KEY_BYTES",
    "MAX_STATE",
    "MAX_TEXT",
    "MODEL_FILE",
    "ONNX_DTYPES",
    "PREPARE_FILE",
    "READ_VERSIONS",
    "REPLAY_FILE",
    "SCHEMA_VERSION",
    "SCORE_DTYPES",
    "SIGNATURE_FILE",
    "STATE_DTYPES",
    "TOP_FIELDS",
    "_FILE_NAME",
    "_SHA256",
    "Budget",
    "Bundle",
    "DecisionSpec",
    "FrameSpec",
    "Manifest",
    "StateSpec",
    "TensorSpec",
    "_check_decision_size",
    "_check_digest",
    "_check_graph",
    "_check_hmac",
    "_check_opset",
    "_check_prepare",
    "_check_state",
    "_decision",
    "_describe_outputs",
    "_first_nonfinite",
    "_frame",
    "_jsonable",
    "_one_line",
    "_output_shape",
    "_prepare",
    "_proto_fields",
    "_read_manifest",
    "_session",
    "_short_list",
    "_slip_columns",
    "_state",
    "_tensors",
    "_text",
    "_training",
    "_varint",
    "load_bundle",
    "manifest_digest",
    "manifest_hmac",
    "onnx_dtype",
    "onnx_opsets",
    "read_key",
    "run_with_deadline",
    "sign_manifest",
    "validate_manifest",
    "write_bundle",
]
