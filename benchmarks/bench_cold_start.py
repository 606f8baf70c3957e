"""Cold start of ``slipkit-run``: process start to the first decision, per test bundle.

Run: ``.venv/bin/python benchmarks/bench_cold_start.py [--python PY] [--repeats 5]``.

The three bundles of ``bench_runtime_loop.py`` (FSR linear, BioTac MLP, TacTip RBF SVM;
random weights) are written to a temporary folder. For each, three commands are timed
from ``subprocess`` start to exit, ``--repeats`` times, interleaved (median and max, ms):

* ``python``: ``PY -c pass``, the interpreter alone;
* ``import``: ``PY -c "import slipkit.runtime.cli"``, the runtime's imports (numpy,
  onnxruntime);
* ``first decision``: ``slipkit-run <bundle> --replay <bundle>/replay.npz --frames W
  --json OUT`` with W the bundle's window, so the run ends right after its first
  decision: argument checks, bundle load and verification (checksums, the graph's
  first call under its deadline), the first W frames, the summary and the JSON write.
  This is an upper bound on process start -> first decision.

``PY`` defaults to this interpreter; pass a runtime-only venv's python (numpy +
onnxruntime only, docs/deploy.md "Installing on a gripper PC (offline)") to time what a
gripper PC runs: its ``slipkit-run`` is the one next to ``PY``. The first repeat pays a
cold file cache; the median is the warm figure.
"""

from __future__ import annotations

import os

# One core: pin BLAS/OpenMP pools before numpy loads (children inherit it).
for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import statistics  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_runtime_loop import build_cases  # noqa: E402


def _time(cmd: list[str]) -> float:
    """Wall time of one command, ms (it must succeed)."""
    t0 = time.perf_counter()
    done = subprocess.run(cmd, capture_output=True, text=True, check=False)
    ms = (time.perf_counter() - t0) * 1e3
    if done.returncode != 0:
        raise SystemExit(f"{' '.join(cmd)} failed:\n{done.stderr[-2000:]}")
    return ms


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--python",
        default=sys.executable,
        help="interpreter whose slipkit-run is timed (default: this one)",
    )
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args(argv)
    py = Path(args.python)
    run = py.parent / "slipkit-run"
    versions = subprocess.run(
        [
            str(py),
            "-c",
            "import sys, numpy, onnxruntime; print(sys.version.split()[0], "
            "numpy.__version__, onnxruntime.__version__)",
        ],
        capture_output=True,
        text=True,
        check=True,
    ).stdout.split()
    print(
        f"{py}: Python {versions[0]}, numpy {versions[1]}, onnxruntime {versions[2]}; "
        f"{os.cpu_count()} CPUs; {args.repeats} repeats; ms, process start to exit"
    )
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        cases = build_cases(root / "bundles", 200)
        cmds: dict[str, list[str]] = {
            "python": [str(py), "-c", "pass"],
            "import": [str(py), "-c", "import slipkit.runtime.cli"],
        }
        for bundle, _ in cases:
            cmds[f"first decision {bundle.manifest.name}"] = [
                str(run),
                str(bundle.path),
                "--replay",
                str(bundle.path / "replay.npz"),
                "--frames",
                str(bundle.manifest.frame.window),
                "--json",
                str(root / "out.json"),
            ]
        times: dict[str, list[float]] = {name: [] for name in cmds}
        for _ in range(args.repeats):  # interleaved: drift hits every row alike
            for name, cmd in cmds.items():
                times[name].append(_time(cmd))
        decisions = json.loads((root / "out.json").read_text())["decisions"]
    print(f"{'':<32} {'median':>8} {'max':>8}")
    for name, ts in times.items():
        print(f"{name:<32} {statistics.median(ts):>8.0f} {max(ts):>8.0f}")
    print(f"decisions in the last run: {decisions}")


if __name__ == "__main__":
    main()
