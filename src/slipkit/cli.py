"""The ``slipkit`` command: one Hydra app per subcommand, all sharing ``configs/``.

``slipkit <subcommand> key=value ...`` composes ``configs/<subcommand>.yaml`` with
the overrides (``-m`` for multirun, ``--cfg job`` to print the config) and calls
the subcommand's function. Only working subcommands are listed here.
"""

from __future__ import annotations

import importlib
import sys
from collections.abc import Callable, Sequence
from typing import Any

#: subcommand -> ("module:function", one-line help). Each function takes the composed DictConfig.
SUBCOMMANDS: dict[str, tuple[str, str]] = {
    "import": (
        "slipkit.data.commands:import_main",
        "convert a recording (source=...) into a dataset folder",
    ),
    "info": (
        "slipkit.data.commands:info_main",
        "print a dataset's summary (dataset=<folder>)",
    ),
    "demo": (
        "slipkit.demo:demo_main",
        "the whole pipeline on built-in defaults: simulate, train, compare, export, replay, report",
    ),
    "simulate": (
        "slipkit.sim.commands:simulate_main",
        "simulate a scene into a dataset folder (scene=...)",
    ),
    "train": (
        "slipkit.train.commands:train_main",
        "train a model (experiment=...) and write a run folder",
    ),
    "evaluate": (
        "slipkit.train.commands:evaluate_main",
        "score a run on a dataset it was not trained on (run=... dataset=...)",
    ),
    "compare": (
        "slipkit.compare.commands:compare_main",
        "learned vs analytic on one split: accuracy, delay, compute per frame (comparison=...)",
    ),
    "export": (
        "slipkit.export.commands:export_main",
        "write an ONNX bundle of a trained run (run=... out=exports/<name>)",
    ),
}


def _usage() -> str:
    width = max(map(len, SUBCOMMANDS))
    rows = "\n".join(
        f"  {name:<{width}}  {text}" for name, (_, text) in SUBCOMMANDS.items()
    )
    return (
        "usage: slipkit <subcommand> [key=value ...] [-m] [--cfg job] [--help]\n\n"
        f"subcommands:\n{rows}\n\n"
        "Each subcommand is a Hydra app composed from configs/<subcommand>.yaml;\n"
        "`slipkit <subcommand> --help` lists its config groups and defaults."
    )


def _resolve(target: str) -> Callable[[Any], Any]:
    module, func = target.split(":")
    fn: Callable[[Any], Any] = getattr(importlib.import_module(module), func)
    return fn


def main(argv: Sequence[str] | None = None) -> None:
    """Entry point of the ``slipkit`` console script."""
    args = list(sys.argv[1:] if argv is None else argv)
    if not args or args[0] in {"-h", "--help", "help"}:
        print(_usage())
        return
    sub, rest = args[0], args[1:]
    if sub not in SUBCOMMANDS:
        print(f"slipkit: unknown subcommand {sub!r}\n\n{_usage()}", file=sys.stderr)
        raise SystemExit(2)

    try:
        import hydra
    except ImportError:  # a runtime-only install (gripper PC): numpy + onnxruntime
        print(
            f"slipkit {sub}: needs the training extra: pip install 'slipkit[train]' "
            "(a gripper PC runs bundles with slipkit-run)",
            file=sys.stderr,
        )
        raise SystemExit(2) from None

    from slipkit import config_dir
    from slipkit.errors import SlipkitError

    task = _resolve(SUBCOMMANDS[sub][0])

    def run(cfg: Any) -> Any:
        try:
            return task(cfg)
        except SlipkitError as exc:
            # Bad input is the user's to fix: say what and where, no traceback.
            print(f"slipkit {sub}: error: {exc}", file=sys.stderr)
            raise SystemExit(2) from exc

    run.__name__ = sub.replace("-", "_")
    run.__module__ = __name__
    saved = sys.argv
    sys.argv = [f"slipkit {sub}", *rest]
    try:
        hydra.main(version_base="1.3", config_path=str(config_dir()), config_name=sub)(
            run
        )()
    finally:
        sys.argv = saved


if __name__ == "__main__":  # pragma: no cover
    main()
