"""One registry of exporters: estimator class -> function returning an :class:`ExportedGraph`.

Modelled on sklearn-onnx's converter registry: each model family's module ends
with its :func:`register_exporter` call, duplicates are refused unless
``overwrite=True``, and :func:`exporter_for` walks the estimator's MRO, so a
subclass uses its parent's exporter unless it registers its own.

Every graph an exporter returns obeys the same contract (checked by
:func:`finalize_model`): one float32 (or float64) input with a symbolic batch
dimension, IR
version :data:`IR_VERSION` (onnx 1.23's ``helper.make_model`` writes IR 14, which
onnxruntime 1.31 refuses), default-domain opset in :data:`SUPPORTED_OPSETS`, and
``onnx.checker.check_model`` passes.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np
import onnx

from slipkit._registry import Registry
from slipkit.errors import SlipkitError

#: IR version written into every graph: onnxruntime 1.31 refuses IR 14 (onnx 1.23's
#: default); 10 is what onnx 1.16 wrote, so older runtimes on a gripper PC load it too.
IR_VERSION = 10
#: Default-domain opsets every exporter may target (both run on onnxruntime 1.31).
SUPPORTED_OPSETS = (17, 18)
#: The opset exporters use unless told otherwise.
DEFAULT_OPSET = 17

ScoreMethod = Literal[
    "decision_function", "predict_proba", "predict", "transform", "forward"
]


class ExportError(SlipkitError):
    """An estimator cannot be exported (unknown class, unsupported setting, bad graph)."""


class NoExporterError(ExportError, TypeError):
    """No exporter is registered for the estimator's class or any of its bases."""


@dataclass(frozen=True)
class ExportedGraph:
    """An ONNX graph and what its input and outputs mean.

    Parameters
    ----------
    model : onnx.ModelProto
        The graph (IR :data:`IR_VERSION`, float32 or float64 input, checked).
    input_name : str
        Name of the single input.
    input_shape : tuple of (str or int)
        Input shape; the first entry is the symbolic batch dimension (``"batch"``).
    output_names : tuple of str
        All graph outputs, in order.
    score_output : str
        The output holding the score the decision is made on.
    score_meaning : str
        What the score is, e.g. ``"decision_function: positive for classes_[1]
        ('static')"``, ``"probabilities in classes_ order"``, ``"regression
        outputs ['fx', 'fy', 'fz'] (N)"``.
    score_method : {"decision_function", "predict_proba", "predict", "transform", "forward"}
        The estimator method whose output the score reproduces (used by
        :func:`slipkit.export.parity.check_parity`).
    opset : int
        Default-domain opset of the graph.
    classes : tuple of str or None
        Class labels in ``classes_`` order, None for regressors and transforms.
    threshold : float or None
        Binary decision rule on a 1-D score: ``classes[1]`` where
        ``score > threshold``, else ``classes[0]`` (0.0 for a decision function).
        None when the decision is the arg-max of per-class scores or there is none.
    network : bool
        True for neural networks (parity then also requires max |score
        difference| <= 1e-4).
    input_meaning : str
        What the input holds (feature names or the raw frame layout).
    features : dict or None
        Feature computation done inside the graph (e.g. the TacTip pin-velocity
        features: ``{"kind": "tactip_pin_velocity", "n_pins": 127, ...}``), None
        when the graph takes the estimator's own features.
    producers : dict of str to str
        Versions of the libraries that built the graph.
    input_dtype : {"float32", "float64"}
        The graph input's dtype, what the runtime feeds (its ``INPUT_DTYPES``):
        float32 for most graphs; float64 where a cast of a float32 input would be
        a node of its own (the FSR and LWR graphs compute in float64).
    strict : bool
        The threshold rule's comparison: ``score > threshold`` (True, scikit-learn's
        ``predict``) or ``score >= threshold`` (False, the analytic detectors).
    """

    model: onnx.ModelProto
    input_name: str
    input_shape: tuple[str | int, ...]
    output_names: tuple[str, ...]
    score_output: str
    score_meaning: str
    score_method: ScoreMethod
    opset: int
    classes: tuple[str, ...] | None = None
    threshold: float | None = None
    network: bool = False
    input_meaning: str = "features"
    features: dict[str, Any] | None = None
    producers: dict[str, str] = field(default_factory=dict)
    input_dtype: str = "float32"
    strict: bool = True

    def serialize(self) -> bytes:
        """The ONNX file's bytes."""
        return bytes(self.model.SerializeToString())

    def decision(self) -> dict[str, Any] | None:
        """The score -> class rule, in the bundle manifest's terms; None without classes.

        ``{"output", "rule": "threshold", "column": 0, "classes", "threshold",
        "strict": True}`` (``classes[1]`` where ``score > threshold``, as
        scikit-learn's ``predict``) for a 1-D score, ``{"output", "rule":
        "argmax", "classes"}`` for per-class scores. Which class is slip is the
        caller's to add (``"positive"``).
        """
        if self.classes is None:
            return None
        if self.threshold is not None:
            return {
                "output": self.score_output,
                "rule": "threshold",
                "column": 0,
                "classes": list(self.classes),
                "threshold": self.threshold,
                "strict": self.strict,
            }
        return {
            "output": self.score_output,
            "rule": "argmax",
            "classes": list(self.classes),
        }

    def describe(self) -> dict[str, Any]:
        """Everything but the graph, as JSON-ready values (for a bundle manifest)."""
        return {
            "input": {
                "name": self.input_name,
                "shape": list(self.input_shape),
                "dtype": self.input_dtype,
                "meaning": self.input_meaning,
            },
            "outputs": list(self.output_names),
            "score": {
                "output": self.score_output,
                "meaning": self.score_meaning,
                "method": self.score_method,
                "threshold": self.threshold,
            },
            "classes": None if self.classes is None else list(self.classes),
            "decision": self.decision(),
            "network": self.network,
            "features": self.features,
            "opset": self.opset,
            "ir_version": int(self.model.ir_version),
            "producers": dict(self.producers),
        }


Exporter = Callable[..., ExportedGraph]

_EXPORTERS: Registry[type, Exporter] = Registry(
    "exporter", error=ExportError, n_args=1, key_type=type
)


def register_exporter(cls: type, fn: Exporter, *, overwrite: bool = False) -> None:
    """Register ``fn(estimator, **options) -> ExportedGraph`` for ``cls``.

    Parameters
    ----------
    cls : type
        The estimator class (subclasses inherit the exporter).
    fn : callable
        The exporter.
    overwrite : bool
        Replace an exporter already registered for exactly ``cls``; without it a
        second registration raises, as in sklearn-onnx's ``register_converter``.
    """
    _EXPORTERS.register(cls, fn, overwrite=overwrite)


def unregister_exporter(cls: type) -> None:
    """Remove the exporter registered for exactly ``cls`` (KeyError if none)."""
    _EXPORTERS.unregister(cls)


def exporter_for(estimator: Any) -> Exporter:
    """The exporter of ``estimator``'s class, or of its nearest registered base class.

    Raises
    ------
    NoExporterError
        When neither the class nor any base in its MRO has an exporter.
    """
    cls = estimator if isinstance(estimator, type) else type(estimator)
    found = _EXPORTERS.for_class(cls)
    if found is not None:
        return found
    raise NoExporterError(
        f"no ONNX exporter is registered for {_qualified(cls)} or its bases "
        f"({', '.join(_qualified(b) for b in cls.__mro__[1:])}); register one with "
        "slipkit.export.register_exporter(cls, fn)"
    )


def export(estimator: Any, **options: Any) -> ExportedGraph:
    """Export ``estimator`` with its registered exporter (options passed through)."""
    return exporter_for(estimator)(estimator, **options)


def registered() -> dict[type, Exporter]:
    """A copy of the registry (class -> exporter)."""
    return dict(_EXPORTERS)


@dataclass(frozen=True)
class StreamContext:
    """What a stream detector's runtime-steps hook may read at export.

    Attributes
    ----------
    stream : str
        The stream the detector reads.
    channels : list of str
        Its channels, in the graph's order.
    train_ids : list
        The run's training trials (not held out).
    held : list
        The held-out trials (:class:`slipkit.export.deploy.HeldOutTrial`).
    frames : callable
        ``frames(trial_ids)`` -> the trials' raw frames (as ``held``).
    """

    stream: str
    channels: list[str]
    train_ids: list[Any]
    held: list[Any]
    frames: Callable[[list[Any]], list[Any]]


@dataclass
class RuntimeSteps:
    """What the runtime must do around a detector's graph, and what the bundle deploys.

    Attributes
    ----------
    steps : list of dict
        Preprocessing steps of the runtime's op registry, in order.
    notes : list of str
        Lines for the bundle's notes (what a user must know on the gripper PC).
    model : estimator or None
        The estimator the graph is exported from when it differs from the trained one
        (e.g. a fixed baseline instead of a per-recording one); None: the trained one.
    """

    steps: list[dict[str, Any]] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    model: Any = None


RuntimeStepsHook = Callable[[Any, StreamContext], RuntimeSteps]

_RUNTIME_STEPS: Registry[type, RuntimeStepsHook] = Registry(
    "runtime steps", error=ExportError, n_args=2, key_type=type
)


def register_runtime_steps(
    cls: type, fn: RuntimeStepsHook, *, overwrite: bool = False
) -> None:
    """Register ``fn(detector, context) -> RuntimeSteps`` for a stream detector class.

    An exporter whose graph needs steps outside it (a rest level latched on the
    gripper PC, a fixed baseline) registers them here beside the graph, as
    sklearn-onnx registers a shape calculator with a converter, so the deployer asks
    the detector's class instead of testing it. Subclasses inherit the entry.
    """
    _RUNTIME_STEPS.register(cls, fn, overwrite=overwrite)


def runtime_steps(detector: Any, context: StreamContext) -> RuntimeSteps:
    """The registered steps of ``detector``'s class (nearest base), or none."""
    hook = _RUNTIME_STEPS.for_class(type(detector))
    return RuntimeSteps() if hook is None else hook(detector, context)


def _qualified(obj: Any) -> str:
    return (
        f"{getattr(obj, '__module__', '?')}.{getattr(obj, '__qualname__', repr(obj))}"
    )


def check_opset(opset: int) -> int:
    """``opset`` if onnxruntime 1.31 runs it (one of :data:`SUPPORTED_OPSETS`), else ExportError."""
    if int(opset) not in SUPPORTED_OPSETS:
        raise ExportError(f"opset must be one of {SUPPORTED_OPSETS}; got {opset!r}")
    return int(opset)


def finalize_model(
    model: onnx.ModelProto, extra_inputs: tuple[str, ...] = ()
) -> onnx.ModelProto:
    """Stamp IR :data:`IR_VERSION` and the producer, then run ``onnx.checker.check_model``.

    Raises ExportError when the default-domain opset is not supported, the input
    is not a single float32 or float64 tensor with a symbolic first dimension, or
    the checker
    fails. ``extra_inputs``: inputs the runtime feeds besides the frame input (a
    prepare graph's tensor), left out of the one-input rule.
    """
    from slipkit import __version__

    model.ir_version = IR_VERSION
    model.producer_name = "slipkit"
    model.producer_version = __version__
    # skl2onnx 1.20 lists the default domain twice; keep one entry per domain.
    versions: dict[str, int] = {}
    for o in model.opset_import:
        domain = "" if o.domain == "ai.onnx" else o.domain
        versions[domain] = max(versions.get(domain, 0), int(o.version))
    del model.opset_import[:]
    model.opset_import.extend(
        onnx.helper.make_opsetid(d, v) for d, v in versions.items()
    )
    default = [v for d, v in versions.items() if d == ""]
    if len(default) != 1 or default[0] not in SUPPORTED_OPSETS:
        raise ExportError(
            f"graph {model.graph.name!r} uses default-domain opset {default}; "
            f"expected one of {SUPPORTED_OPSETS}"
        )
    initializers = {t.name for t in model.graph.initializer}
    inputs = [
        i
        for i in model.graph.input
        if i.name not in initializers and i.name not in extra_inputs
    ]
    if len(inputs) != 1:
        raise ExportError(
            f"graph {model.graph.name!r} has {len(inputs)} inputs; expected one"
        )
    tensor = inputs[0].type.tensor_type
    if tensor.elem_type not in (onnx.TensorProto.FLOAT, onnx.TensorProto.DOUBLE):
        raise ExportError(f"input {inputs[0].name!r} is not float32 or float64")
    dims = tensor.shape.dim
    if not dims or not dims[0].dim_param:
        raise ExportError(
            f"input {inputs[0].name!r} has no symbolic batch dimension: {dims}"
        )
    try:
        onnx.checker.check_model(model, full_check=True)
    except onnx.checker.ValidationError as err:
        raise ExportError(
            f"graph {model.graph.name!r} fails the checker: {err}"
        ) from err
    return model


def input_spec(model: onnx.ModelProto) -> tuple[str, tuple[str | int, ...]]:
    """Name and shape (symbolic dims as their names) of the graph's single input."""
    initializers = {t.name for t in model.graph.initializer}
    (inp,) = [i for i in model.graph.input if i.name not in initializers]
    shape = tuple(
        d.dim_param if d.dim_param else int(d.dim_value)
        for d in inp.type.tensor_type.shape.dim
    )
    return inp.name, shape


def producers(**extra: str) -> dict[str, str]:
    """Versions of slipkit, onnx and numpy, plus ``extra`` (e.g. ``torch="2.13.0"``)."""
    from slipkit import __version__

    return {
        "slipkit": __version__,
        "onnx": onnx.__version__,
        "numpy": np.__version__,
        **extra,
    }
