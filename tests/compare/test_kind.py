"""A comparison row's kind: a detector that fits a model says so with its ``slipkit_kind`` tag."""

from __future__ import annotations

from slipkit.compare.commands import _kind


def test_logistic_onset_detectors_are_learned_and_rules_analytic() -> None:
    """The FSR and SlipTack logistic onset detectors show as learned, their rules as analytic,
    and a model in the model slot as learned."""
    kinds = [
        _kind({"_target_": "slipkit.families.fsr.onset.FSROnsetLogistic"}, True),
        _kind(
            {"_target_": "slipkit.families.sliptack.onset.SlipTackOnsetLogistic"}, True
        ),
        _kind({"_target_": "slipkit.families.fsr.onset.FSROnset"}, True),
        _kind({"_target_": "slipkit.models.svm.TacTipSVM"}, False),
    ]
    assert ["learned", "learned", "analytic", "learned"] == kinds
