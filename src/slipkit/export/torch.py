"""Export of torch modules and skorch-based estimators with ``torch.onnx.export``.

Uses the TorchScript-based exporter (``dynamo=False``): in torch 2.13 the
default dynamo exporter needs onnxscript and fixed a GRU's batch size to 1,
where the legacy exporter keeps a dynamic batch axis. After export the IR
version is set to 10 and the graph checked (:func:`finalize_model`).

A skorch-based estimator is taken apart by duck typing (:func:`find_torch_parts`):

* its torch module: ``module_`` (a skorch net, or a slipkit estimator that keeps
  the fitted net's module as ``module_``), or the last step of a Pipeline;
* its input standardisation: ``scaler_`` or ``x_scaler_`` with ``mean_`` /
  ``scale_`` (StandardScaler), or StandardScaler steps before the net in a
  Pipeline;
* its output de-standardisation: ``y_scaler_`` (regressors trained on
  standardised targets);
* the output non-linearity of a bare skorch net (``predict_proba`` applies
  softmax / sigmoid to the module's logits; skorch's own
  ``_get_predict_nonlinearity``).

These become constant ops around the module in the graph, or, next to a
``Sequential``'s first / last ``Linear``, are folded into that layer's weights and
bias (:func:`fold_standardisation`: fewer nodes), so the graph's score is what the
estimator returns: ``predict_proba`` for classifiers, ``predict``
for regressors.
"""

from __future__ import annotations

import copy
import io
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from typing import Any, cast

import numpy as np
import onnx
import torch
from numpy.typing import NDArray
from torch import nn

from slipkit.export.registry import (
    DEFAULT_OPSET,
    ExportedGraph,
    ExportError,
    ScoreMethod,
    check_opset,
    finalize_model,
    producers,
    register_exporter,
)

INPUT = "input"
SCORE = "score"


@dataclass
class TorchParts:
    """What a skorch-based estimator computes, as separate pieces.

    Attributes
    ----------
    module : torch.nn.Module
        The trained module.
    x_mean, x_scale : ndarray or None
        Input standardisation ``(x - x_mean) / x_scale`` (None: none).
    y_mean, y_scale : ndarray or None
        Output de-standardisation ``y * y_scale + y_mean`` (None: none).
    nonlinearity : callable or None
        Applied to the module output before de-standardisation (skorch's
        predict non-linearity of a bare net), None for identity.
    n_features : int or None
        Input width, when the estimator records it.
    classes : tuple of str or None
        Class labels of a classifier.
    score_method : {"predict_proba", "predict"}
        The estimator method the exported output reproduces.
    """

    module: nn.Module
    x_mean: NDArray[np.float64] | None = None
    x_scale: NDArray[np.float64] | None = None
    y_mean: NDArray[np.float64] | None = None
    y_scale: NDArray[np.float64] | None = None
    nonlinearity: Callable[[torch.Tensor], torch.Tensor] | None = None
    n_features: int | None = None
    classes: tuple[str, ...] | None = None
    score_method: ScoreMethod = "predict"


def _scaler_arrays(
    scaler: Any, n: int | None
) -> tuple[NDArray[np.float64] | None, NDArray[np.float64] | None]:
    if scaler is None:
        return None, None
    if not (hasattr(scaler, "mean_") and hasattr(scaler, "scale_")):
        raise ExportError(
            f"{type(scaler).__name__} is not a fitted StandardScaler-like object (mean_, scale_)"
        )
    mean = None if scaler.mean_ is None else np.asarray(scaler.mean_, np.float64)
    scale = None if scaler.scale_ is None else np.asarray(scaler.scale_, np.float64)
    width = len(mean) if mean is not None else len(scale) if scale is not None else n
    if width is None:
        return None, None
    return (
        np.zeros(width) if mean is None else mean,
        np.ones(width) if scale is None else scale,
    )


def _compose(
    first: tuple[NDArray[np.float64] | None, NDArray[np.float64] | None],
    second: tuple[NDArray[np.float64] | None, NDArray[np.float64] | None],
) -> tuple[NDArray[np.float64] | None, NDArray[np.float64] | None]:
    """Two standardisations in a row as one: ``((x - m1)/s1 - m2)/s2 = (x - m)/s``."""
    m1, s1 = first
    m2, s2 = second
    if m1 is None or s1 is None:
        return second
    if m2 is None or s2 is None:
        return first
    return m1 + m2 * s1, s1 * s2


def _is_net(obj: Any) -> bool:
    return hasattr(obj, "module_") and isinstance(obj.module_, nn.Module)


def _classes(obj: Any) -> tuple[str, ...] | None:
    classes = getattr(obj, "classes_", None)
    return None if classes is None else tuple(str(c) for c in classes)


def find_torch_parts(estimator: Any) -> TorchParts:
    """Split a skorch-based estimator into module, scalers and non-linearity (duck typing).

    Accepts a skorch net (anything with a torch ``module_``), an estimator that
    keeps one as ``module_`` next to ``scaler_`` / ``x_scaler_`` / ``y_scaler_``,
    or a Pipeline of StandardScaler-like steps ending in either.

    Raises
    ------
    ExportError
        When no torch module is found, or a Pipeline step before the net is not a
        StandardScaler-like transform.
    """
    steps = getattr(estimator, "steps", None)
    if steps is not None:
        *front, (_, last) = steps
        parts = find_torch_parts(last)
        x: tuple[NDArray[np.float64] | None, NDArray[np.float64] | None] = (None, None)
        for name, step in front:
            if step is None or step == "passthrough":
                continue
            if not (hasattr(step, "mean_") and hasattr(step, "scale_")):
                raise ExportError(
                    f"pipeline step {name!r} ({type(step).__name__}) is not a StandardScaler-like "
                    "transform; only scalers may precede the torch net"
                )
            x = _compose(x, _scaler_arrays(step, None))
        parts.x_mean, parts.x_scale = _compose(x, (parts.x_mean, parts.x_scale))
        n = getattr(estimator, "n_features_in_", None)
        parts.n_features = parts.n_features if n is None else int(n)
        if parts.classes is None:
            parts.classes = _classes(estimator)
        return parts
    if not _is_net(estimator):
        raise ExportError(
            f"{type(estimator).__name__} has no torch module_ (nor is a Pipeline ending in one)"
        )
    n = getattr(estimator, "n_features_in_", None)
    scaler = getattr(estimator, "scaler_", None)
    if scaler is None:
        scaler = getattr(estimator, "x_scaler_", None)
    x_mean, x_scale = _scaler_arrays(scaler, n)
    y_mean, y_scale = _scaler_arrays(getattr(estimator, "y_scaler_", None), None)
    classes = _classes(estimator)
    nonlinearity = None
    # A bare skorch net: predict_proba applies its predict non-linearity to the
    # module output; a wrapper estimator calls module_ itself (what it returns is
    # checked by parity).
    get_nl = getattr(estimator, "_get_predict_nonlinearity", None)
    if callable(get_nl) and hasattr(estimator, "initialized_"):
        nl = get_nl()
        nonlinearity = None if getattr(nl, "__name__", "") == "_identity" else nl
    return TorchParts(
        module=estimator.module_,
        x_mean=x_mean,
        x_scale=x_scale,
        y_mean=y_mean,
        y_scale=y_scale,
        nonlinearity=nonlinearity,
        n_features=None if n is None else int(n),
        classes=classes,
        score_method="predict_proba"
        if classes is not None and hasattr(estimator, "predict_proba")
        else "predict",
    )


def fold_standardisation(parts: TorchParts) -> TorchParts:
    """The same computation with the scalers folded into a Sequential's end Linear layers.

    ``(x - m) / s`` before a first ``nn.Linear`` ``(W, b)`` is the layer ``(W / s, b -
    (W / s) m)``, and ``y s_y + m_y`` after a last one (no predict non-linearity) is
    ``(s_y W, s_y b + m_y)``: the graph then has no Sub / Mul / Add around the Gemms
    (each ~0.3 us of node dispatch at batch 1, where the whole 3x10 force MLP is a
    few us). Folded in float64, stored in float32 on a copy of the module; other
    modules, or a Sequential not starting (ending) with a Linear, keep the scaler ops.

    Parameters
    ----------
    parts : TorchParts
        From :func:`find_torch_parts`; not modified.

    Returns
    -------
    TorchParts
        ``parts`` itself when nothing folds, else a copy with a new module and the
        folded scalers set to None.
    """
    module = parts.module
    if not isinstance(module, nn.Sequential) or len(module) == 0:
        return parts
    first, last = module[0], module[len(module) - 1]
    fold_in = (
        isinstance(first, nn.Linear)
        and first.bias is not None
        and parts.x_mean is not None
        and parts.x_scale is not None
    )
    fold_out = (
        isinstance(last, nn.Linear)
        and last.bias is not None
        and parts.nonlinearity is None
        and parts.y_mean is not None
        and parts.y_scale is not None
    )
    if not (fold_in or fold_out):
        return parts
    folded = copy.deepcopy(module)
    with torch.no_grad():
        if fold_in:
            lin = cast(torch.nn.Linear, folded[0])
            w = lin.weight.detach().double().numpy() / np.asarray(parts.x_scale)
            b = lin.bias.detach().double().numpy() - w @ np.asarray(parts.x_mean)
            lin.weight.copy_(torch.as_tensor(w, dtype=lin.weight.dtype))
            lin.bias.copy_(torch.as_tensor(b, dtype=lin.bias.dtype))
        if fold_out:
            lin = cast(torch.nn.Linear, folded[len(folded) - 1])
            ys = np.asarray(parts.y_scale, dtype=np.float64)
            w = lin.weight.detach().double().numpy() * ys[:, None]
            b = lin.bias.detach().double().numpy() * ys + np.asarray(parts.y_mean)
            lin.weight.copy_(torch.as_tensor(w, dtype=lin.weight.dtype))
            lin.bias.copy_(torch.as_tensor(b, dtype=lin.bias.dtype))
    return replace(
        parts,
        module=folded,
        x_mean=None if fold_in else parts.x_mean,
        x_scale=None if fold_in else parts.x_scale,
        y_mean=None if fold_out else parts.y_mean,
        y_scale=None if fold_out else parts.y_scale,
    )


class _Deployed(nn.Module):
    """module with the standardisations and non-linearity as constant ops around it."""

    x_mean: torch.Tensor
    x_inv: torch.Tensor
    y_mean: torch.Tensor
    y_scale: torch.Tensor

    def __init__(self, parts: TorchParts) -> None:
        super().__init__()
        self.inner = parts.module
        self.nonlinearity = parts.nonlinearity
        self.scale_in = parts.x_mean is not None and parts.x_scale is not None
        self.scale_out = parts.y_mean is not None and parts.y_scale is not None
        f32 = torch.float32
        if self.scale_in:
            self.register_buffer("x_mean", torch.as_tensor(parts.x_mean, dtype=f32))
            self.register_buffer(
                "x_inv", torch.as_tensor(1.0 / np.asarray(parts.x_scale), dtype=f32)
            )
        if self.scale_out:
            self.register_buffer("y_mean", torch.as_tensor(parts.y_mean, dtype=f32))
            self.register_buffer("y_scale", torch.as_tensor(parts.y_scale, dtype=f32))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        if self.scale_in:
            x = (x - self.x_mean) * self.x_inv
        y = self.inner(x)
        if self.nonlinearity is not None:
            y = self.nonlinearity(y)
        if self.scale_out:
            y = y * self.y_scale + self.y_mean
        return y


def export_torch_module(
    module: nn.Module,
    *,
    input_shape: Sequence[int],
    parts: TorchParts | None = None,
    score_method: ScoreMethod = "forward",
    score_meaning: str | None = None,
    classes: Sequence[str] | None = None,
    opset: int = DEFAULT_OPSET,
) -> ExportedGraph:
    """Export a torch module with a dynamic batch axis (legacy exporter, ``dynamo=False``).

    Parameters
    ----------
    module : torch.nn.Module
        The module; exported in eval mode (its training flag is restored after).
    input_shape : sequence of int
        Shape of one input sample, without the batch axis, e.g. ``(n_features,)``
        or ``(n_steps, n_channels)`` for a GRU.
    parts : TorchParts, optional
        Standardisations and non-linearity to wrap around the module (from
        :func:`find_torch_parts`); ``parts.module`` must be ``module``. Scalers
        next to a Sequential's first / last Linear are folded into its weights
        (:func:`fold_standardisation`; ``module`` itself is not changed).
    score_method : str
        The method the output reproduces (``"forward"``: the module itself).
    score_meaning : str, optional
        Text for :attr:`ExportedGraph.score_meaning`.
    classes : sequence of str, optional
        Class labels when the output is per-class probabilities (decision: arg-max).
    opset : int
        Default-domain opset (17 or 18).

    Returns
    -------
    ExportedGraph
        Input ``"input"`` of shape ``("batch", *input_shape)``, output ``"score"``.
    """
    opset = check_opset(opset)
    was_training = module.training
    module.eval()
    if parts is not None:
        parts = fold_standardisation(parts)
    wrapped = _Deployed(parts if parts is not None else TorchParts(module=module))
    example = torch.zeros((2, *(int(s) for s in input_shape)), dtype=torch.float32)
    buffer = io.BytesIO()
    try:
        with warnings.catch_warnings(), torch.no_grad():
            # The legacy exporter warns that it is deprecated; it is the one that
            # keeps a GRU's batch dynamic without onnxscript (see module notes).
            warnings.simplefilter("ignore", DeprecationWarning)
            warnings.simplefilter("ignore", FutureWarning)
            warnings.simplefilter("ignore", UserWarning)
            # nn.GRU's input-size checks become trace constants: true for every batch.
            warnings.simplefilter("ignore", torch.jit.TracerWarning)
            torch.onnx.export(
                wrapped,
                (example,),
                buffer,  # type: ignore[arg-type]  # the legacy exporter writes to file objects
                input_names=[INPUT],
                output_names=[SCORE],
                dynamic_axes={INPUT: {0: "batch"}, SCORE: {0: "batch"}},
                opset_version=opset,
                dynamo=False,
            )
    finally:
        module.train(was_training)
    model = finalize_model(onnx.load_from_string(buffer.getvalue()))
    out_dims = model.graph.output[0].type.tensor_type.shape.dim
    shape_text = "x".join(d.dim_param or str(d.dim_value) for d in out_dims)
    return ExportedGraph(
        model=model,
        input_name=INPUT,
        input_shape=("batch", *(int(s) for s in input_shape)),
        output_names=tuple(o.name for o in model.graph.output),
        score_output=SCORE,
        score_meaning=score_meaning or f"module output ({shape_text})",
        score_method=score_method,
        opset=opset,
        classes=None if classes is None else tuple(str(c) for c in classes),
        network=True,
        input_meaning=f"float32 tensor of shape (batch, {', '.join(map(str, input_shape))})",
        producers=producers(torch=torch.__version__),
    )


def export_skorch_estimator(
    estimator: Any,
    *,
    input_shape: Sequence[int] | None = None,
    opset: int = DEFAULT_OPSET,
) -> ExportedGraph:
    """Export a skorch-based estimator (see :func:`find_torch_parts`) with its scalers inside.

    Parameters
    ----------
    estimator : object
        Fitted skorch net, estimator keeping ``module_``, or Pipeline ending in one.
    input_shape : sequence of int, optional
        One sample's shape without the batch axis; default ``(n_features_in_,)``.
    opset : int
        Default-domain opset (17 or 18).

    Returns
    -------
    ExportedGraph
        Output ``"score"``: ``predict_proba`` (classes_ order) for classifiers,
        ``predict`` for regressors.
    """
    parts = find_torch_parts(estimator)
    if input_shape is None:
        if parts.n_features is None:
            raise ExportError(
                f"{type(estimator).__name__} does not record n_features_in_; pass input_shape="
            )
        input_shape = (parts.n_features,)
    if parts.score_method == "predict_proba":
        meaning = "probabilities in classes_ order"
    else:
        meaning = "regression outputs of predict"
        names = getattr(estimator, "target_names_", None) or getattr(
            estimator, "output_names_", None
        )
        if names is not None:
            meaning += f" {list(names)}"
    return export_torch_module(
        parts.module,
        input_shape=input_shape,
        parts=parts,
        score_method=parts.score_method,
        score_meaning=meaning,
        classes=parts.classes,
        opset=opset,
    )


def _export_module(
    module: nn.Module, *, input_shape: Sequence[int], opset: int = DEFAULT_OPSET
) -> ExportedGraph:
    """Registry entry for a bare ``nn.Module``: its forward output is the score."""
    return export_torch_module(module, input_shape=input_shape, opset=opset)


register_exporter(nn.Module, _export_module)


def _register_skorch() -> None:
    try:
        from skorch import NeuralNet
    except ImportError:  # skorch is in the train extra; plain torch export still works
        return
    register_exporter(NeuralNet, export_skorch_estimator)


_register_skorch()


def _register_slipkit_nets() -> None:
    """slipkit's skorch-based estimators keep ``module_`` + scalers (not NeuralNet subclasses)."""
    from slipkit.models.window import WindowCNN, WindowGRU, WindowMLP

    for cls in (WindowMLP, WindowCNN, WindowGRU):
        register_exporter(cls, export_skorch_estimator)


_register_slipkit_nets()
