"""DAVIS incipient-slip onset rule: short frames, a one-sided loss of contact.

Incipient slip shrinks the contact from its trailing side: pixels lose contact
(positive events) while almost none gain it (negative events), frame after frame as the
shear grows. A vibration incident shifts the whole patch, so one side loses contact
while the other gains it: both polarities in similar amounts. Pressing only gains
contact (negative events). :class:`DavisOnset` keeps the polarity rule's frames and
filter (:class:`slipkit.baselines.davis.DavisPolarity`: opening, closing and area
filter of each polarity) on shorter frames (5 ms) and changes the decision:

    slip when ``pos >= min_pos_px`` and ``neg <= neg_ratio * pos``

(filtered areas, px), i.e. :func:`onset_score` > 0. Persistence (a loss that lasts) is
the deployment's debounce: ``k`` consecutive slip frames (``configs/closedloop/davis.yaml``).
The score is shared with the exported graph (:mod:`slipkit.export.davis_onset`), so the
batch, streaming and ONNX decisions are the same numbers.
"""

from __future__ import annotations

from numbers import Integral, Real
from typing import Any, ClassVar

import numpy as np
from numpy.typing import ArrayLike, NDArray
from sklearn.utils._param_validation import Interval

from slipkit.baselines.davis import NONE, SLIP, VIBRATION, DavisPolarity, FrameResult

FloatArray = NDArray[np.float64]


def onset_score(
    pos_area: ArrayLike, neg_area: ArrayLike, *, min_pos_px: int, neg_ratio: float
) -> FloatArray:
    """``min(pos - min_pos_px + 0.5, neg_ratio pos - neg + 0.5)`` (px): > 0 is slip.

    Areas are whole pixels, so the first term is > 0 exactly when ``pos >= min_pos_px``;
    the second is > 0 when ``neg < neg_ratio pos + 0.5`` (``neg <= neg_ratio pos`` up
    to half a pixel).
    """
    pos = np.asarray(pos_area, dtype=np.float64)
    neg = np.asarray(neg_area, dtype=np.float64)
    return np.minimum(pos - float(min_pos_px) + 0.5, float(neg_ratio) * pos - neg + 0.5)


class DavisOnset(DavisPolarity):
    """One-sided contact loss on short event frames (module docstring).

    Parameters
    ----------
    frame_s : float
        Event-frame length (s; 0.005: a decision every 5 ms).
    width_px, height_px, opening_px, opening_shape, closing_px, min_area_px
        As :class:`~slipkit.baselines.davis.DavisPolarity` (the same filter).
    min_pos_px : int
        Smallest filtered positive area (px) that counts as a loss of contact.
    neg_ratio : float
        Largest negative area per px of positive area in a slip frame (a vibration
        incident gains about as much contact as it loses).

    Frames with a positive area that fail the rule are ``VIBRATION`` in
    :meth:`frames` (code 1), as in the polarity rule.
    """

    _parameter_constraints: ClassVar[dict[str, list[Any]]] = {
        **DavisPolarity._parameter_constraints,
        "min_pos_px": [Interval(Integral, 1, None, closed="left")],
        "neg_ratio": [Interval(Real, 0, None, closed="left")],
    }

    def __init__(
        self,
        *,
        frame_s: float = 0.005,
        width_px: int = 190,
        height_px: int = 180,
        opening_px: int = 2,
        opening_shape: str = "lines",
        closing_px: int = 3,
        min_area_px: int = 8,
        min_pos_px: int = 8,
        neg_ratio: float = 0.25,
    ) -> None:
        super().__init__(
            frame_s=frame_s,
            width_px=width_px,
            height_px=height_px,
            opening_px=opening_px,
            opening_shape=opening_shape,
            closing_px=closing_px,
            min_area_px=min_area_px,
        )
        self.min_pos_px = min_pos_px
        self.neg_ratio = neg_ratio

    def score(self, pos_area: ArrayLike, neg_area: ArrayLike) -> FloatArray:
        """:func:`onset_score` with this detector's parameters."""
        return onset_score(
            pos_area,
            neg_area,
            min_pos_px=int(self.min_pos_px),
            neg_ratio=float(self.neg_ratio),
        )

    def _result(self, f: int, chunk: FloatArray, stress: FloatArray) -> FrameResult:
        r = super()._result(f, chunk, stress)
        pos, neg = r.pos_area_px, r.neg_area_px
        slip = bool(self.score(pos, neg) > 0)
        incident = SLIP if slip else (VIBRATION if pos > 0 else NONE)
        return FrameResult(
            frame=r.frame,
            t_start_s=r.t_start_s,
            t_end_s=r.t_end_s,
            pos_area_px=pos,
            neg_area_px=neg,
            incident=incident,
        )


__all__ = ["DavisOnset", "onset_score"]
