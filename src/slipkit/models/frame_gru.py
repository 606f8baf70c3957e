"""A frame-by-frame recurrent slip detector: a small GRU whose state runs across a recording.

:class:`FrameGRUDetector` keeps the :class:`~slipkit.baselines.base.StreamDetector`
contract (``fit(X, y, segments)``, ``decision_function``, ``threshold_`` from the
training ROC, batch and streaming forms equal), so the stream-detection task scores
it beside the analytic detectors. Per sample: standardise the frame (mean and scale
of the training samples) -> one GRU step (hidden state carried from the previous
sample, zeros at a recording's start) -> a linear head; the score is the slip logit
at that sample. Unlike :class:`~slipkit.models.window.WindowGRU`, which runs a whole
window from a zero state, the state here lives as long as the recording, so the
runtime carries it between frames (the bundle's ``state`` section,
``docs/deploy.md``, "Recurrent state").

A non-finite sample scores ``-inf`` and the state restarts at zeros at the next
sample, as the runtime loop does on a bad frame; training treats every finite run of
samples as a recording of its own.

Training is truncated backpropagation through time: the training recordings are
stacked as a padded batch, each epoch walks them in chunks of ``chunk`` samples with
the state carried from one chunk to the next (detached), and the per-sample binary
cross-entropy (positives weighted by the class ratio, padding masked) is minimised by
Adam. Hand-written rather than skorch: skorch's loop shuffles independent samples
and cannot carry a state across the chunks of one recording.

Scores are computed in numpy (float64) from the trained weights, one GRU step per
sample, so the batch form and the streaming form run the same recurrence.
"""

from __future__ import annotations

from numbers import Integral, Real
from typing import Any, ClassVar

import numpy as np
from numpy.typing import ArrayLike, NDArray
from sklearn.utils._param_validation import Interval

from slipkit.baselines.base import FloatArray, StreamDetector, segment_bounds

__all__ = ["FrameGRUDetector", "GRUStream", "gru_step"]


def _sigmoid(x: FloatArray) -> FloatArray:
    return 0.5 * (1.0 + np.tanh(0.5 * x))  # overflow-free form of 1 / (1 + e^-x)


def gru_step(
    gi: FloatArray, h: FloatArray, w_hh: FloatArray, b_hh: FloatArray
) -> FloatArray:
    """One GRU step in torch's parametrisation (gates r, z, n), float64.

    Parameters
    ----------
    gi : ndarray (3 * H,)
        The input projection ``W_ih x + b_ih`` of this sample.
    h : ndarray (H,)
        The previous state.
    w_hh : ndarray (3 * H, H)
    b_hh : ndarray (3 * H,)

    Returns
    -------
    ndarray (H,)
        The next state ``(1 - z) * n + z * h``.
    """
    n_h = len(h)
    gh = w_hh @ h + b_hh
    r = _sigmoid(gi[:n_h] + gh[:n_h])
    z = _sigmoid(gi[n_h : 2 * n_h] + gh[n_h : 2 * n_h])
    n = np.tanh(gi[2 * n_h :] + r * gh[2 * n_h :])
    out: FloatArray = (1.0 - z) * n + z * h
    return out


class GRUStream:
    """The streaming form of :class:`FrameGRUDetector` (one GRU step per sample)."""

    def __init__(self, det: FrameGRUDetector) -> None:
        self.det = det
        self.reset()

    def reset(self) -> None:
        """Zero state (a new recording starts)."""
        self.h = np.zeros(int(self.det.hidden))

    def update(self, sample: ArrayLike) -> tuple[float, bool]:
        """Feed one sample (n_channels,); return (slip logit, slip decision)."""
        x = np.asarray(sample, dtype=np.float64)
        if not np.all(np.isfinite(x)):
            self.reset()
            return -np.inf, False
        d = self.det
        gi = d.w_ih_ @ ((x - d.mean_) / d.scale_) + d.b_ih_
        self.h = gru_step(gi, self.h, d.w_hh_, d.b_hh_)
        s = float(d.w_out_ @ self.h + d.b_out_)
        return s, s >= d.threshold_


class FrameGRUDetector(StreamDetector):
    """A per-frame GRU slip detector with a recording-long state (see the module doc).

    Parameters
    ----------
    hidden : int
        GRU state size.
    chunk : int
        Samples per truncated-backpropagation chunk.
    epochs : int
        Passes over the training recordings.
    lr : float
        Adam learning rate.
    weight_decay : float
        Adam L2 weight decay.
    random_state : int
        Seed of the weight initialisation (torch, forked: the caller's RNG is left alone).
    threshold : float or None
        Slip when the logit ``>= threshold``; None: the training ROC's point.
    roc_point : {"youden", "closest"}
        ROC point of the per-sample ROC.

    Attributes
    ----------
    mean_, scale_ : ndarray (n_channels,)
        Standardisation of the inputs, from the finite training samples (channel units).
    w_ih_, b_ih_, w_hh_, b_hh_ : ndarray
        GRU weights (torch's ``weight_ih_l0`` ... layout: gates r, z, n).
    w_out_ : ndarray (hidden,)
    b_out_ : float
        The linear head: logit = ``w_out_ . h + b_out_``.
    loss_ : list of float
        Mean training loss per epoch.
    threshold_, classes_, roc_fpr_, roc_tpr_, roc_thresholds_, auc_, tpr_, tnr_, fpr_, fnr_, n_features_in_
        See :class:`~slipkit.baselines.base.StreamDetector`.
    """

    _parameter_constraints: ClassVar[dict[str, list[Any]]] = {
        **StreamDetector._parameter_constraints,
        "hidden": [Interval(Integral, 1, 256, closed="both")],
        "chunk": [Interval(Integral, 1, None, closed="left")],
        "epochs": [Interval(Integral, 1, None, closed="left")],
        "lr": [Interval(Real, 0, None, closed="neither")],
        "weight_decay": [Interval(Real, 0, None, closed="left")],
        "random_state": [Interval(Integral, 0, None, closed="left")],
    }
    n_channels: ClassVar[int | None] = None

    def __init__(
        self,
        *,
        hidden: int = 12,
        chunk: int = 64,
        epochs: int = 40,
        lr: float = 0.01,
        weight_decay: float = 0.0,
        random_state: int = 0,
        threshold: float | None = None,
        roc_point: str = "youden",
    ) -> None:
        super().__init__(threshold=threshold, roc_point=roc_point)
        self.hidden = hidden
        self.chunk = chunk
        self.epochs = epochs
        self.lr = lr
        self.weight_decay = weight_decay
        self.random_state = random_state

    @staticmethod
    def _finite_runs(X: FloatArray) -> list[tuple[int, int]]:
        """(start, stop) of every run of finite samples of one recording."""
        ok = np.isfinite(X).all(axis=1)
        edges = np.flatnonzero(np.diff(np.concatenate([[0], ok.view(np.int8), [0]])))
        return [(int(a), int(b)) for a, b in zip(edges[::2], edges[1::2], strict=True)]

    def fit(
        self, X: ArrayLike, y: ArrayLike, *, segments: ArrayLike | None = None
    ) -> FrameGRUDetector:
        """Train the GRU on the finite runs of every recording, then choose the threshold."""
        self._validate_params()
        Xv = self._check_X(X, reset=True)
        yv = np.asarray(y).astype(int).reshape(-1)
        if yv.shape != (len(Xv),):
            raise ValueError(f"y must have shape ({len(Xv)},); got {yv.shape}")
        runs = [
            (a + p, a + q)
            for a, b in segment_bounds(len(Xv), segments)
            for p, q in self._finite_runs(Xv[a:b])
        ]
        if not runs:
            raise ValueError("no finite training samples")
        finite = np.concatenate([Xv[a:b] for a, b in runs])
        labels = np.concatenate([yv[a:b] for a, b in runs])
        if len(np.unique(labels)) < 2:
            raise ValueError(
                f"training samples hold only classes {np.unique(labels).tolist()}; "
                "need slip and non-slip samples"
            )
        self.mean_ = finite.mean(axis=0)
        scale = finite.std(axis=0)
        self.scale_ = np.where(scale > 0, scale, 1.0)
        self._train([((Xv[a:b] - self.mean_) / self.scale_, yv[a:b]) for a, b in runs])
        super().fit(Xv, yv, segments=segments)
        return self

    def _train(self, recs: list[tuple[FloatArray, NDArray[np.int_]]]) -> None:
        # Deferred import: torch is needed to train only (scoring is numpy).
        import torch
        from torch import nn

        n, t_max, c = len(recs), max(len(x) for x, _ in recs), recs[0][0].shape[1]
        xs = np.zeros((n, t_max, c), dtype=np.float32)
        ys = np.zeros((n, t_max), dtype=np.float32)
        mask = np.zeros((n, t_max), dtype=np.float32)
        for i, (x, yy) in enumerate(recs):
            xs[i, : len(x)], ys[i, : len(x)], mask[i, : len(x)] = x, yy, 1.0
        n_pos = float((ys * mask).sum())
        pos_weight = (float(mask.sum()) - n_pos) / max(n_pos, 1.0)
        threads = torch.get_num_threads()
        with torch.random.fork_rng(devices=[]):
            torch.manual_seed(int(self.random_state))
            torch.set_num_threads(1)
            try:
                gru = nn.GRU(c, int(self.hidden), batch_first=True)
                head = nn.Linear(int(self.hidden), 1)
                params = [*gru.parameters(), *head.parameters()]
                opt = torch.optim.Adam(
                    params, lr=float(self.lr), weight_decay=float(self.weight_decay)
                )
                loss_fn = nn.BCEWithLogitsLoss(
                    pos_weight=torch.tensor(pos_weight), reduction="none"
                )
                xt, yt, mt = map(torch.from_numpy, (xs, ys, mask))
                step = int(self.chunk)
                self.loss_ = []
                for _ in range(int(self.epochs)):
                    h = torch.zeros(1, n, int(self.hidden))
                    total = 0.0
                    for s in range(0, t_max, step):
                        out, h = gru(xt[:, s : s + step], h)
                        logit = head(out).squeeze(-1)
                        m = mt[:, s : s + step]
                        loss = (loss_fn(logit, yt[:, s : s + step]) * m).sum() / m.sum()
                        opt.zero_grad()
                        loss.backward()
                        opt.step()
                        h = h.detach()
                        total += float(loss.detach()) * float(m.sum())
                    self.loss_.append(total / float(mask.sum()))
            finally:
                torch.set_num_threads(threads)

        def arr(p: Any) -> FloatArray:
            return np.asarray(p.detach().numpy(), dtype=np.float64)

        self.w_ih_, self.b_ih_ = arr(gru.weight_ih_l0), arr(gru.bias_ih_l0)
        self.w_hh_, self.b_hh_ = arr(gru.weight_hh_l0), arr(gru.bias_hh_l0)
        self.w_out_ = arr(head.weight).reshape(-1)
        self.b_out_ = float(arr(head.bias)[0])

    def _scores(self, X: FloatArray) -> FloatArray:
        out = np.full(len(X), -np.inf)
        for a, b in self._finite_runs(X):
            gi = ((X[a:b] - self.mean_) / self.scale_) @ self.w_ih_.T + self.b_ih_
            h = np.zeros(int(self.hidden))
            hs = np.empty((b - a, len(h)))
            for i, g in enumerate(gi):
                h = hs[i] = gru_step(g, h, self.w_hh_, self.b_hh_)
            out[a:b] = hs @ self.w_out_ + self.b_out_
        return out

    def _new_stream(self) -> GRUStream:
        return GRUStream(self)
