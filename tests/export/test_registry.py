"""The exporter registry: duplicates refused, MRO lookup, unknown classes named, graph contract."""

from __future__ import annotations

import json

import numpy as np
import onnx
import pytest
from sklearn.linear_model import LogisticRegression
from torch import nn

from slipkit.export import (
    ExportError,
    NoExporterError,
    export,
    exporter_for,
    register_exporter,
)
from slipkit.export.registry import (
    IR_VERSION,
    SUPPORTED_OPSETS,
    check_opset,
    registered,
    unregister_exporter,
)
from slipkit.families.tactip.export.svm import export_tactip_svm
from slipkit.models import TacTipSVM


class Widget:
    """A class nobody registered."""


class SubWidget(Widget):
    """A subclass of it."""


def _fake_exporter(estimator, **options):
    raise AssertionError("never called")


@pytest.fixture
def widget_registered():
    """Widget registered with a fake exporter for the test, removed after."""
    register_exporter(Widget, _fake_exporter)
    yield
    unregister_exporter(Widget)


def test_duplicate_registration_is_refused_unless_overwrite(widget_registered):
    """A second exporter for the same class raises; overwrite=True replaces it."""

    def other(estimator, **options):
        raise AssertionError("never called")

    with pytest.raises(ExportError, match=r"already registered for .*Widget"):
        register_exporter(Widget, other)
    assert _fake_exporter is exporter_for(Widget())
    register_exporter(Widget, other, overwrite=True)
    assert other is exporter_for(Widget())


def test_subclasses_inherit_their_parents_exporter(widget_registered):
    """exporter_for walks the MRO: SubWidget and a TacTipSVM subclass use their base's exporter."""

    class MySVM(TacTipSVM):
        pass

    assert _fake_exporter is exporter_for(SubWidget())
    assert export_tactip_svm is exporter_for(MySVM())
    assert export_tactip_svm is exporter_for(TacTipSVM)


def test_unknown_class_error_names_the_class():
    """An unregistered class raises NoExporterError naming it and telling how to register."""
    with pytest.raises(
        NoExporterError, match=r"test_registry\.Widget .*register_exporter"
    ):
        exporter_for(Widget())
    with pytest.raises(TypeError, match="needs a class"):
        register_exporter("Widget", _fake_exporter)  # type: ignore[arg-type]


def test_every_family_is_registered():
    """Importing slipkit.export registers TacTipSVM, scikit-learn classes and torch modules."""
    table = registered()
    assert {TacTipSVM, LogisticRegression, nn.Module} <= set(table)


def test_unsupported_opsets_are_refused():
    """Only opsets onnxruntime 1.31 runs (17, 18) are accepted."""
    assert (17, 18) == SUPPORTED_OPSETS
    assert 18 == check_opset(18)
    with pytest.raises(ExportError, match="opset must be one of"):
        check_opset(21)


@pytest.mark.parametrize("opset", SUPPORTED_OPSETS)
def test_every_graph_meets_the_contract(opset: int):
    """SVM, scikit-learn and torch graphs: IR 10, float32 input with symbolic batch, checker passes."""
    rng = np.random.default_rng(0)
    X = rng.normal(size=(40, 4))
    y = np.where(X[:, 0] > 0, "slip", "static")
    graphs = [
        export(TacTipSVM(C=1.0).fit(X, y), opset=opset),
        export(LogisticRegression().fit(X, y), opset=opset),
        export(nn.Linear(4, 2), input_shape=(4,), opset=opset),
    ]
    for graph in graphs:
        model = graph.model
        assert IR_VERSION == model.ir_version == 10
        assert opset == graph.opset
        assert opset in [o.version for o in model.opset_import if o.domain == ""]
        (inp,) = [i for i in model.graph.input if i.name == graph.input_name]
        assert onnx.TensorProto.FLOAT == inp.type.tensor_type.elem_type
        assert "batch" == graph.input_shape[0]
        assert graph.score_output in graph.output_names
        onnx.checker.check_model(model, full_check=True)
        described = json.loads(json.dumps(graph.describe()))
        assert 10 == described["ir_version"]
    assert "threshold" == graphs[0].decision()["rule"]
    assert 0.0 == graphs[0].decision()["threshold"]
    assert "argmax" == graphs[1].decision()["rule"]
    assert graphs[2].decision() is None
