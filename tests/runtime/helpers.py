"""Tiny ONNX graphs, manifests and bundles shared by the runtime tests."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view
from onnx import TensorProto, helper, numpy_helper

from slipkit.runtime import write_bundle
from slipkit.runtime.bundle import sign_manifest

N_CHANNELS = 3
WINDOW = 4
RATE_HZ = 100.0


def linear_graph(
    weights: np.ndarray,
    bias: np.ndarray | float,
    *,
    input_name: str = "X",
    output_name: str = "score",
    batch: int | str = 1,
    opset: int = 17,
) -> bytes:
    """``score = X @ W + B`` for ``X`` of shape (batch, n_in); W of shape (n_in,) or (n_in, n_out)."""
    w = np.asarray(weights, dtype=np.float32)
    w = w.reshape(len(w), -1)
    n_in, n_out = w.shape
    b = np.broadcast_to(np.asarray(bias, dtype=np.float32), (n_out,)).reshape(1, n_out)
    nodes = [
        helper.make_node("MatMul", [input_name, "W"], ["xw"]),
        helper.make_node("Add", ["xw", "B"], [output_name]),
    ]
    graph = helper.make_graph(
        nodes,
        "linear",
        [helper.make_tensor_value_info(input_name, TensorProto.FLOAT, [batch, n_in])],
        [helper.make_tensor_value_info(output_name, TensorProto.FLOAT, [batch, n_out])],
        initializer=[numpy_helper.from_array(w, "W"), numpy_helper.from_array(b, "B")],
    )
    model = helper.make_model(
        graph, opset_imports=[helper.make_opsetid("", opset)], producer_name="tests"
    )
    # onnx 1.23's helper writes IR 14, which onnxruntime 1.31 refuses.
    model.ir_version = 10
    return bytes(model.SerializeToString())


def manifest(
    n_in: int,
    *,
    threshold: float | None = 0.0,
    channels: int = N_CHANNELS,
    window: int = WINDOW,
    hop: int = 1,
    k: int = 2,
    preprocessing: list[dict[str, Any]] | None = None,
    budget: tuple[float, float] = (10.0, 1.0),
    decision: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """A valid manifest (without ``files``) for a linear graph with ``n_in`` inputs."""
    man: dict[str, Any] = {
        "name": "linear",
        "frame": {
            "streams": ["force"],
            "channels": [f"c{i}" for i in range(channels)],
            "shape": [channels],
            "window": window,
            "hop": hop,
            "rate_hz": RATE_HZ,
        },
        "preprocessing": preprocessing or [],
        "inputs": [{"name": "X", "dtype": "float32", "shape": [1, n_in]}],
        "outputs": [{"name": "score", "dtype": "float32"}],
        "decision": decision
        or {
            "output": "score",
            "rule": "threshold",
            "column": 0,
            "classes": ["static", "slip"],
            "positive": "slip",
        },
        "threshold": threshold,
        "debounce": {"k": k},
        "budget_ms": {"frame_period": budget[0], "p99": budget[1]},
        "session": {"intra_op_num_threads": 1, "warmup": 2},
        "opset": 17,
        "producer": {"slipkit": "0.1.0", "onnx": "1.23.2"},
        "training": {"data_fingerprint": "abc123", "metrics": {"test": {"f1": 0.9}}},
    }
    return man


def frames(n: int = 200, channels: int = N_CHANNELS, seed: int = 0) -> np.ndarray:
    """Random frames (n, channels) as float32 (what a UDP sender carries)."""
    return np.random.default_rng(seed).normal(size=(n, channels)).astype(np.float32)


def windows(x: np.ndarray, window: int) -> np.ndarray:
    """All windows of ``window`` frames, oldest first: (n - window + 1, window, ...)."""
    return np.moveaxis(sliding_window_view(x, window, axis=0), -1, 1)


def gap_threshold(scores: np.ndarray) -> float:
    """A threshold in the widest gap between sorted scores near the median, so that
    float32 rounding cannot flip any decision."""
    s = np.sort(scores)
    mid = len(s) // 2
    lo, hi = mid - len(s) // 4, mid + len(s) // 4
    gaps = np.diff(s[lo:hi])
    j = lo + int(np.argmax(gaps))
    return float((s[j] + s[j + 1]) / 2)


class LinearCase:
    """A standardize + linear bundle over random frames and its numpy reference scores."""

    def __init__(
        self,
        root: Path,
        *,
        window: int = WINDOW,
        hop: int = 1,
        k: int = 2,
        seed: int = 0,
        budget: tuple[float, float] = (10.0, 1.0),
        name: str = "linear",
    ) -> None:
        rng = np.random.default_rng(seed)
        self.frames = frames(200, seed=seed)
        self.timestamps = np.arange(len(self.frames)) / RATE_HZ
        self.mean = rng.normal(size=N_CHANNELS)
        self.scale = rng.uniform(0.5, 2.0, size=N_CHANNELS)
        n_in = window * N_CHANNELS
        self.w = rng.normal(size=n_in)
        self.b = 0.1
        win = windows(self.frames.astype(np.float64), window)
        x = ((win - self.mean) / self.scale).reshape(len(win), -1)
        self.scores = x @ self.w + self.b
        self.threshold = gap_threshold(self.scores)
        self.window, self.hop, self.k = window, hop, k
        man = manifest(
            n_in,
            threshold=self.threshold,
            window=window,
            hop=hop,
            k=k,
            budget=budget,
            preprocessing=[
                {"op": "standardize", "mean": self.mean, "scale": self.scale}
            ],
        )
        man["name"] = name
        self.path = write_bundle(
            root / name,
            linear_graph(self.w, self.b),
            man,
            replay=(self.frames, self.timestamps),
        )

    def edit_manifest(self, fn: Any, *, resign: bool = True) -> None:
        """Apply ``fn(manifest_dict)`` to the written manifest.json (to break it).

        With ``resign`` (default) the manifest's digest is recomputed, as a tool that
        rewrites manifests would, so the edit reaches the field checks behind it.
        """
        edit_manifest(self.path, fn, resign=resign)


def edit_manifest(bundle: Path, fn: Any, *, resign: bool = True) -> None:
    """Apply ``fn(manifest_dict)`` to ``bundle/manifest.json``; re-sign it unless told not to."""
    path = bundle / "manifest.json"
    man = json.loads(path.read_text())
    fn(man)
    if resign and isinstance(man, dict):
        man = sign_manifest(man)
    path.write_text(json.dumps(man))


def pin_bundle(root: Path, n_pins: int = 4, seed: int = 0) -> Path:
    """A TacTip-like bundle: raw pin frames -> pin_velocity_features -> standardize -> linear."""
    rng = np.random.default_rng(seed)
    n_feat = 2 * n_pins
    man = manifest(
        n_feat,
        threshold=0.0,
        channels=2 * n_pins,
        window=2,
        preprocessing=[
            {"op": "pin_velocity_features", "variant": "dr_dtheta"},
            {"op": "standardize", "mean": np.zeros(n_feat), "scale": np.ones(n_feat)},
        ],
        budget=(8.333, 0.833),
    )
    man["name"] = "pins"
    man["frame"]["streams"] = ["pins"]
    man["frame"]["channels"] = [f"x{i}" for i in range(n_pins)] + [
        f"y{i}" for i in range(n_pins)
    ]
    pins = np.cumsum(rng.normal(scale=0.1, size=(80, 2 * n_pins)), axis=0)
    return write_bundle(
        root / "pins",
        linear_graph(rng.normal(size=n_feat), 0.0),
        man,
        replay=(pins, np.arange(80) / 120.0),
    )


def run_cli_reporting_modules(
    python: str, bundle: Path, out_json: Path
) -> tuple[dict[str, Any], list[str]]:
    """Run ``python -X importtime -m slipkit.runtime.cli <bundle> --report-modules --json``.

    Returns the summary JSON and every module name ``-X importtime`` saw imported.
    Reusable by a test that installs ``slipkit[runtime]`` into a fresh venv: pass that
    venv's python.
    """
    import subprocess

    proc = subprocess.run(
        [
            python,
            "-X",
            "importtime",
            "-m",
            "slipkit.runtime.cli",
            str(bundle),
            "--report-modules",
            "--json",
            str(out_json),
        ],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert 0 == proc.returncode, proc.stderr[-2000:]
    imported = [
        line.split("|")[-1].strip()
        for line in proc.stderr.splitlines()
        if line.startswith("import time:") and "imported package" not in line
    ]
    return json.loads(out_json.read_text()), imported


#: BioTacSP-DoS's direction classes (slipkit.data.importers.biotacsp_dos.CLASSES).
DOS_CLASSES = ("n", "e", "s", "w", "cw", "aw", "t")


def dos_like_bundle(root: Path, seed: int = 0) -> Path:
    """A DoS-shaped bundle: 24 electrodes at 100 Hz, windows of 5 every 2 frames, 7-class argmax.

    Slip classes are every direction (all but ``t``); the budget comes from the data's
    100 Hz (10 ms frame, p99 1 ms), as ``slipkit export`` writes it for DoS.
    """
    rng = np.random.default_rng(seed)
    channels, window = 24, 5
    man = manifest(
        window * channels,
        threshold=None,
        channels=channels,
        window=window,
        hop=2,
        k=1,
        budget=(10.0, 1.0),
        decision={
            "output": "score",
            "rule": "argmax",
            "classes": list(DOS_CLASSES),
            "positive": "n",
            "slip_classes": list(DOS_CLASSES[:-1]),
        },
    )
    man["name"] = "dos_like"
    man["frame"]["streams"] = ["electrodes"]
    man["budget_ms"]["source"] = "data_rate_hz"
    man["training"] = {
        "refit_on_all_data": True,
        "held_out": False,
        "scored_on": "4-fold leave-objects-out CV (outer folds), before the refit",
        "replay": {
            "trials": 7,
            "frames": 7 * 60,
            "held_out": False,
            "by_class": dict.fromkeys(DOS_CLASSES, 1),
            "note": "parity and latency, not accuracy",
        },
    }
    x = 2000.0 + np.cumsum(rng.normal(size=(7 * 60, channels)), axis=0)
    return write_bundle(
        root / "dos_like",
        linear_graph(rng.normal(scale=1e-3, size=(window * channels, 7)), 0.0),
        man,
        replay=(x, np.arange(len(x)) / RATE_HZ),
    )
