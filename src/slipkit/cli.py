"""The ``slipkit`` command: one Hydra app per subcommand, all sharing ``configs/``.

``slipkit <subcommand> key=value ...`` composes ``configs/<subcommand>.yaml`` with
the overrides (``-m`` for multirun, ``--cfg job`` to print the config) and calls
the subcommand's function. Only working subcommands are listed here.
"""

from __future__ import annotations

import contextlib
import datetime as dt
import importlib
import io
import os
import sys
import tempfile
import traceback
import warnings
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import Any, NoReturn, TextIO

from slipkit._options import composition_message, one_line

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
    "export-dataset": (
        "slipkit.data.commands:export_dataset_main",
        "write a dataset for other tools: LeRobot v3.0, trials as episodes (dataset=... out=...)",
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
    "sweep": (
        "slipkit.train.optuna_sweep:sweep_main",
        "an Optuna study over train runs (experiment=... search=...); workers on any machine share it",
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
    "closedloop": (
        "slipkit.closedloop.commands:closedloop_main",
        "closed-loop grasp: slip distance, drops, extra grip per detector bundle (scenario=...)",
    ),
}


#: subcommand -> {option: config group}: ``option=X`` picks the group's option ``X`` when
#: ``configs/<group>/X.yaml`` exists, so dotted overrides of the group apply to ``X``
#: (``slipkit closedloop scenario=fsr closedloop.plant.latency_s=0.05``).
GROUP_OPTIONS: dict[str, dict[str, str]] = {"closedloop": {"scenario": "closedloop"}}


def _pick_groups(sub: str, rest: Sequence[str]) -> list[str]:
    """``rest`` with each ``option=X`` of :data:`GROUP_OPTIONS` written as ``<group>=X``.

    Left as it is when an ``X`` (or one of a ``-m`` sweep's ``X,Y``) has no config
    file: the command refuses it, naming the option and the ones there are.
    """
    from slipkit import config_dir

    options = GROUP_OPTIONS.get(sub, {})
    given = dict(arg.partition("=")[::2] for arg in rest if "=" in arg)
    out = []
    for arg in rest:
        key, eq, value = arg.partition("=")
        group = options.get(key)
        names = value.split(",")
        if (
            eq
            and group
            and all((config_dir() / group / f"{n}.yaml").is_file() for n in names)
        ):
            if given.get(group, value) != value:
                _fail(
                    sub,
                    f"error: {key}={value} and {group}={given[group]} name different "
                    f"options; give one of them",
                    2,
                )
            arg = f"{group}={value}"
        out.append(arg)
    return out


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


def _close_progress_bars() -> None:
    """End any live tqdm bar, so the message starts on its own line, not after a bar."""
    tqdm_module = sys.modules.get("tqdm")
    bars = getattr(getattr(tqdm_module, "tqdm", None), "_instances", None) or ()
    for bar in list(bars):
        with contextlib.suppress(
            Exception
        ):  # a bar that cannot close must not hide the error
            bar.close()


def _fail(sub: str, message: str, status: int) -> NoReturn:
    _close_progress_bars()
    print(f"slipkit {sub}: {one_line(message)}", file=sys.stderr)
    raise SystemExit(status)


def log_dir() -> Path:
    """Where an internal error's full traceback is written: ``$SLIPKIT_LOG_DIR``, else
    ``<system temp dir>/slipkit-logs``."""
    given = os.environ.get("SLIPKIT_LOG_DIR")
    return Path(given) if given else Path(tempfile.gettempdir()) / "slipkit-logs"


def _write_traceback(sub: str, exc: BaseException, argv: Sequence[str]) -> str:
    """Write ``exc``'s traceback to a new log file; its path, or why it could not be written."""
    stamp = dt.datetime.now(dt.UTC).strftime("%Y%m%dT%H%M%SZ")
    try:
        folder = log_dir()
        folder.mkdir(parents=True, exist_ok=True)
        path = folder / f"{sub}-{stamp}-{os.getpid()}.log"
        text = "".join(traceback.format_exception(exc))
        path.write_text(f"slipkit {' '.join([sub, *argv])}\n\n{text}", encoding="utf-8")
    except OSError as err:  # the net must not fail: say why instead of a path
        return f"traceback not written ({err.strerror or err})"
    return f"traceback in {path}"


def _internal_error(sub: str, exc: BaseException, argv: Sequence[str]) -> NoReturn:
    where = _write_traceback(sub, exc, argv)
    _fail(
        sub,
        f"internal error (a bug, please report it): {type(exc).__name__}: {exc} ({where})",
        1,
    )


@contextlib.contextmanager
def _hydra_raises() -> Iterator[None]:
    """Hydra re-raises instead of printing a (stripped) traceback itself.

    ``hydra.main`` reports an exception with ``run_and_report``, which prints a
    traceback unless ``HYDRA_FULL_ERROR`` is set, in which case it re-raises: set,
    every error reaches :func:`main`, which prints one line.
    """
    saved = os.environ.get("HYDRA_FULL_ERROR")
    os.environ["HYDRA_FULL_ERROR"] = "1"
    try:
        yield
    finally:
        if saved is None:
            os.environ.pop("HYDRA_FULL_ERROR", None)
        else:
            os.environ["HYDRA_FULL_ERROR"] = saved


def _is_group_override(override: Any) -> bool:
    """Whether a parsed override picks a config group option (``scene=x``, ``+experiment=x``)."""
    from slipkit import config_dir

    key = str(override.key_or_group)
    return (
        override.package is not None
        or key == "hydra"
        or key.startswith(("hydra.", "hydra/"))
        or (config_dir() / key).is_dir()
    )


def _parse_overrides(overrides: Sequence[str]) -> list[Any]:
    from hydra.core.override_parser.overrides_parser import OverridesParser

    parsed: list[Any] = OverridesParser.create().parse_overrides(list(overrides))
    return parsed


def _reference_config(sub: str, overrides: Sequence[str]) -> Any:
    """``configs/<sub>.yaml`` composed with only the group choices of ``overrides``.

    The keys a command knows before any value override: what ``+key=value`` and a
    mistyped ``key=value`` are checked against. None when even that does not compose.
    """
    from hydra import compose, initialize_config_dir
    from hydra.core.global_hydra import GlobalHydra

    from slipkit import config_dir

    try:
        picked = [o for o in _parse_overrides(overrides) if _is_group_override(o)]
        if any(o.is_sweep_override() for o in picked):
            return None  # -m over groups: each job checks its own choices
        # hydra.* settings change no key of the command's own config
        groups = [
            o.input_line for o in picked if not o.key_or_group.startswith("hydra")
        ]
        if GlobalHydra.instance().is_initialized():
            return compose(config_name=sub, overrides=groups)
        with initialize_config_dir(config_dir=str(config_dir()), version_base="1.3"):
            return compose(config_name=sub, overrides=groups)
    except Exception:  # no reference: the caller keeps Hydra's own message
        return None


def check_added_keys(sub: str, overrides: Sequence[str]) -> None:
    """Refuse ``+key=value`` / ``++key=value`` for a key the command does not know.

    Hydra adds any such key without a word; the code then ignores it (a mistyped
    ``+comparison.dataset.pth``) or passes it to a constructor that refuses it
    (``+model.gama``). Checked against the config composed from the group choices
    alone (:func:`_reference_config`) with :func:`slipkit._options.unknown_key`:
    group choices (``+experiment=x``), Hydra's own ``hydra.*``, a keyword the
    node's ``_target_`` takes and a new entry of a mapping of named entries pass.
    """
    from slipkit._options import unknown_key
    from slipkit.errors import SlipkitError

    try:
        parsed = _parse_overrides(overrides)
    except Exception:  # override syntax: Hydra reports it while composing
        return
    added = [
        o
        for o in parsed
        if (o.is_add() or o.is_force_add()) and not _is_group_override(o)
    ]
    if not added:
        return
    reference = _reference_config(sub, overrides)
    if reference is None:
        return
    for override in added:
        problem = unknown_key(reference, str(override.key_or_group), sub)
        if problem is not None:
            raise SlipkitError(problem)


def _not_in_config(sub: str, exc: Exception, overrides: Sequence[str]) -> str | None:
    """Hydra's "Could not override 'x' ... use +x ... not in struct" as one line with the
    closest keys suggested; None for any other composition error."""
    import re

    from slipkit._options import unknown_key

    found = re.search(r"Could not override '([^']+)'", str(exc))
    if found is None or "not in struct" not in composition_message(exc):
        return None
    key = found.group(1)
    reference = _reference_config(sub, overrides)
    problem = None if reference is None else unknown_key(reference, key, sub)
    if problem is not None:
        return problem
    if reference is not None:
        # The key is one the node takes (a constructor keyword) but the config leaves unset.
        return f"{key}: not set in the config; add it with +{key}=..."
    return f"{key}: unknown key"


class _ArgumentError(Exception):
    """argparse refused the command line (raised instead of printing the usage)."""


def _check_flags(sub: str, rest: Sequence[str]) -> list[str]:
    """Refuse unknown ``--flags`` in one line before Hydra's parser prints its usage.

    Hydra parses the command line with its own ``argparse`` parser, whose ``error``
    prints an eight-line usage; the same parser is run here first with ``error``
    raising instead (the hook argparse documents for subclasses).
    """
    try:
        from hydra._internal.utils import get_args_parser
    except ImportError:  # pragma: no cover - a Hydra without it: Hydra reports itself
        return []
    parser = get_args_parser()

    def error(message: str) -> NoReturn:
        raise _ArgumentError(message)

    parser.error = error  # type: ignore[method-assign]
    try:
        # --version prints and exits here; Hydra prints it again on its own parse.
        with contextlib.redirect_stdout(io.StringIO()):
            args = parser.parse_args(list(rest))
    except _ArgumentError as exc:
        _fail(sub, f"error: {exc} (slipkit {sub} --help lists the options)", 2)
    except SystemExit:
        return []
    # Hydra raises a bare ValueError for these (reported as an internal error
    # otherwise); the same rule as hydra._internal.utils._run_hydra, in one line.
    modes = [
        flag
        for flag, on in (
            ("--multirun", args.multirun),
            ("--cfg", args.cfg is not None),
            ("--run", args.run),
            ("--info", args.info is not None),
            ("--shell-completion", args.shell_completion),
        )
        if on
    ]
    if len(modes) > 1:
        _fail(
            sub,
            f"error: {' and '.join(modes)} cannot be combined: give one of --run, "
            "--multirun, --cfg, --info, --shell-completion",
            2,
        )
    return [str(o) for o in args.overrides]


@contextlib.contextmanager
def _each_warning_once(kind: type[Warning]) -> Iterator[None]:
    """Show each distinct ``kind`` warning (class and text) once while the block runs.

    A warning about the data (e.g. one fixed normal force) is raised on every fit and
    call. The ``"once"`` filter action cannot hold it back: its registry is cleared
    whenever the filters change, which every ``warnings.catch_warnings`` block in
    scikit-learn and joblib does. So the de-duplication sits in ``showwarning``.
    """
    seen: set[tuple[type[Warning], str]] = set()
    shown = warnings.showwarning

    def show(
        message: Warning | str,
        category: type[Warning],
        filename: str,
        lineno: int,
        file: TextIO | None = None,
        line: str | None = None,
    ) -> None:
        if issubclass(category, kind):
            key = (category, str(message))
            if key in seen:
                return
            seen.add(key)
        shown(message, category, filename, lineno, file, line)

    warnings.showwarning = show
    try:
        yield
    finally:
        warnings.showwarning = shown


def _multirun_job_overrides() -> list[str]:
    """A multirun job's overrides (its own values of a ``-m`` sweep); ``[]`` in a single
    run, whose command line :func:`main` checked before Hydra started."""
    from hydra.core.hydra_config import HydraConfig
    from hydra.types import RunMode
    from omegaconf import OmegaConf

    if not HydraConfig.initialized() or HydraConfig.get().mode != RunMode.MULTIRUN:
        return []
    # unresolved: an override's text may hold an interpolation (`out=${nope}`)
    task = OmegaConf.to_container(HydraConfig.get().overrides.task, resolve=False)
    return [str(o) for o in task] if isinstance(task, list) else []


def main(argv: Sequence[str] | None = None) -> None:
    """Entry point of the ``slipkit`` console script.

    Every failure ends in one line on stderr, never a traceback: a
    :class:`~slipkit.errors.SlipkitError` or a config Hydra cannot compose is the
    user's to fix (``slipkit <sub>: error: ...``, status 2); anything else is a bug
    (``slipkit <sub>: internal error ...``, status 1, the full traceback written to a
    log file under :func:`log_dir`).
    """
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

    from hydra.errors import HydraException, InstantiationException
    from omegaconf.errors import (
        InterpolationResolutionError,
        MissingMandatoryValue,
        OmegaConfBaseException,
    )

    from slipkit import config_dir
    from slipkit._options import check_options
    from slipkit.errors import SlipkitError, SlipkitWarning

    try:
        task = _resolve(SUBCOMMANDS[sub][0])
    except Exception as exc:
        _internal_error(sub, exc, rest)

    def run(cfg: Any) -> Any:
        # Everything is caught here, inside the task function: an exception that
        # escaped to Hydra would be printed with "Error executing job" first.
        try:
            check_added_keys(sub, _multirun_job_overrides())
            check_options(cfg, sub)
            with _each_warning_once(SlipkitWarning):
                return task(cfg)
        except SlipkitError as exc:
            # Bad input is the user's to fix: say what and where, no traceback.
            _fail(sub, f"error: {exc}", 2)
        except (MissingMandatoryValue, InterpolationResolutionError) as exc:
            # A `???` left unset or an `${...}` that does not resolve: the config's text.
            key = getattr(exc, "full_key", None)
            first = str(exc).splitlines()[0]
            _fail(sub, f"error: {key}: {first}" if key else f"error: {first}", 2)
        except InstantiationException as exc:
            # A config node whose target refused its arguments (an unknown or missing
            # key added on the command line): the config is the user's to fix.
            _fail(sub, f"error: {exc}", 2)
        except Exception as exc:
            _internal_error(sub, exc, rest)

    rest = _pick_groups(sub, rest)
    overrides = _check_flags(sub, rest)
    try:
        # before Hydra starts: a multirun would make its sweep folder first
        check_added_keys(sub, overrides)
    except SlipkitError as exc:
        _fail(sub, f"error: {exc}", 2)
    run.__name__ = sub.replace("-", "_")
    run.__module__ = __name__
    saved = sys.argv
    sys.argv = [f"slipkit {sub}", *rest]
    try:
        with _hydra_raises():
            hydra.main(
                version_base="1.3", config_path=str(config_dir()), config_name=sub
            )(run)()
    except (HydraException, OmegaConfBaseException) as exc:
        # The overrides do not compose (unknown group option, key not in the config,
        # override syntax): Hydra's message, on one line; a key not in the config
        # with the closest keys it has.
        text = _not_in_config(sub, exc, overrides) or composition_message(exc)
        _fail(sub, f"error: {text}", 2)
    except KeyboardInterrupt:
        _fail(sub, "interrupted", 130)
    except Exception as exc:
        _internal_error(sub, exc, rest)
    finally:
        sys.argv = saved


if __name__ == "__main__":  # pragma: no cover
    main()
