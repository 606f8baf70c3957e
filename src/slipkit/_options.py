"""Checks of the options each ``slipkit`` subcommand reads, before it reads them.

Hydra types an override by its text: ``n_trials=2.9`` arrives as a float,
``seed=abc`` as a string, ``rate_hz=true`` as a bool and a required ``run: ???``
as a missing value. A bare ``int()`` then truncates 2.9 to 2, ``float(True)`` is
1 Hz, and the rest end in tracebacks. :func:`check_options` checks every option of
a subcommand against one table (:data:`OPTIONS`) and raises a
:class:`~slipkit.errors.SlipkitError` naming the first bad one, e.g.
``n_trials=2.9: expected a whole number >= 1``.

Why hand-written rather than OmegaConf structured configs: OmegaConf's typed nodes
have no ranges (``n_trials >= 1``, ``seed < 2**32``), turn ``true`` into nothing
useful for an ``int`` field only after a multi-line error, and a schema per
subcommand would have to mirror every config group the experiments merge in. A
table of small rules keeps the configs as they are and the messages one line.
"""

from __future__ import annotations

import difflib
import fnmatch
import inspect
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

from omegaconf import DictConfig, ListConfig, OmegaConf
from omegaconf.errors import OmegaConfBaseException

from slipkit.errors import SlipkitError

#: largest seed: ``numpy.random.seed`` (which ``slipkit train`` also sets) takes < 2**32
MAX_SEED = 2**32 - 1


def show(value: Any) -> str:
    """``value`` as it would be typed in a Hydra override (``true``, ``null``, ``2.9``)."""
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "true" if value else "false"
    return str(value)


@dataclass(frozen=True)
class Rule:
    """One option's rule.

    Parameters
    ----------
    expected : str
        What the message says was expected (``"a whole number >= 1"``).
    accept : callable
        ``accept(value) -> bool`` for a present, non-null value.
    nullable : bool
        ``null`` is allowed (the option's "not set").
    required : bool
        The option must be given (a ``???`` in the config, or null when not nullable).
    """

    expected: str
    accept: Callable[[Any], bool]
    nullable: bool = False
    required: bool = False

    def null(self) -> Rule:
        """The same rule with ``null`` allowed."""
        return Rule(self.expected + " or null", self.accept, nullable=True)


def _is_number(value: Any) -> bool:
    # bool is an int subclass: `rate_hz=true` must not pass as 1.
    return (
        isinstance(value, int | float)
        and not isinstance(value, bool)
        and math.isfinite(value)
    )


def _is_whole(value: Any) -> bool:
    # 3.0 is a whole number (Hydra reads `n_trials=3.0` as a float); 2.9 is not.
    return _is_number(value) and float(value).is_integer()


def whole(minimum: int = 0, maximum: int | None = None) -> Rule:
    """A whole number in ``[minimum, maximum]`` (``3`` or ``3.0``; never ``2.9`` or ``true``)."""
    text = (
        f"a whole number >= {minimum}"
        if maximum is None
        else f"a whole number in [{minimum}, {maximum}]"
    )
    return Rule(
        text,
        lambda v: _is_whole(v) and v >= minimum and (maximum is None or v <= maximum),
    )


def number(*, minimum: float | None = None, positive: bool = False) -> Rule:
    """A finite number (``> 0`` when ``positive``, ``>= minimum`` when given)."""
    if positive:
        return Rule("a finite number > 0", lambda v: _is_number(v) and v > 0)
    if minimum is not None:
        return Rule(
            f"a finite number >= {minimum:g}",
            lambda v: _is_number(v) and v >= minimum,
        )
    return Rule("a finite number", _is_number)


def within(
    lo: float,
    hi: float,
    unit: str = "",
    *,
    above: bool = False,
    whole_number: bool = False,
    span: bool = False,
) -> Rule:
    """A number in ``[lo, hi]`` (``(lo, hi]`` when ``above``; a whole number when
    ``whole_number``); with ``span`` also ``[a, b]``, ``a <= b`` both in range (drawn per trial).

    The declared range of a physical parameter: a bound keeps a typo or an extreme
    (``hold_s=1e9``, ``substeps=1e9``) from running for hours or asking for terabytes.
    """
    one = _is_whole if whole_number else _is_number

    def inside(v: Any) -> bool:
        return one(v) and (lo < v if above else lo <= v) and v <= hi

    def accept(v: Any) -> bool:
        if span and isinstance(v, ListConfig | list | tuple):
            return len(v) == 2 and inside(v[0]) and inside(v[1]) and v[0] <= v[1]
        return inside(v)

    kind = "a whole number" if whole_number else "a number"
    where = f"{'(' if above else '['}{lo:g}, {hi:g}]" + (f" {unit}" if unit else "")
    text = f"{kind} or [lo, hi] within {where}" if span else f"{kind} in {where}"
    return Rule(text, accept)


FLAG = Rule("true or false", lambda v: isinstance(v, bool))
SEED = whole(0, MAX_SEED)
COUNT = whole(1)
TEXT = Rule(
    "a non-empty text",
    # Hydra reads `name=2024` as an int: a name or path may still be all digits.
    lambda v: (
        isinstance(v, str | int | float)
        and not isinstance(v, bool)
        and str(v).strip() != ""
    ),
)
PATH = Rule("a path", TEXT.accept, required=True)
#: a run / evaluation / bundle name becomes one folder under its parent (``runs/<name>``):
#: ``name=../..`` or ``name=/abs`` would put it anywhere (slipkit._files.check_plain_name)
NAME = Rule(
    "a plain folder name (no '/', '\\', '..' or leading '.')",
    lambda v: (
        TEXT.accept(v)
        and not any(c in str(v) for c in "/\\")
        and not str(v).startswith(".")
        and str(v) == str(v).strip()
    ),
)
RATE = number(positive=True)
#: a simulated sensor's sample rate: from 1 Hz (a trial of a few seconds still has
#: samples) to 100 kHz (tactile sensors sample at tens of kHz at most, the shipped scenes
#: at 30 Hz-2.2 kHz; a TacTip trial at 100 kHz already holds about 10^8 numbers)
SCENE_RATE = within(1.0, 1e5, "Hz")
SEEDS = Rule(
    f"a non-empty list of whole numbers in [0, {MAX_SEED}]",
    lambda v: (
        isinstance(v, ListConfig | list | tuple)
        and len(v) > 0
        and all(SEED.accept(x) for x in v)
    ),
)

#: subcommand -> dotted option -> rule. Options not listed are not checked here (the
#: code that reads them refuses bad values with a SlipkitError of its own).
OPTIONS: dict[str, dict[str, Rule]] = {
    "import": {"path": PATH, "out": PATH, "overwrite": FLAG},
    "info": {"dataset": PATH, "verify": FLAG, "json": FLAG},
    "export-dataset": {
        "dataset": PATH,
        "out": PATH,
        "format": TEXT,
        "stream": TEXT.null(),
        "feature": TEXT.null(),
        "task": TEXT.null(),
        "overwrite": FLAG,
        "verify": FLAG,
    },
    "simulate": {
        "n_trials": COUNT,
        "seed": SEED,
        "out": PATH,
        "overwrite": FLAG,
        "progress": FLAG,
        "summary": FLAG,
    },
    "train": {
        "name": NAME,
        "seed": SEED,
        "runs_dir": TEXT,
        "run_dir": TEXT.null(),
        "overwrite": FLAG,
    },
    "evaluate": {"run": PATH, "dataset": PATH, "name": NAME.null()},
    "sweep": {
        "search": Rule(
            "a search space of configs/search/ (search=<name>)",
            lambda v: isinstance(v, DictConfig),
            required=True,
        ),
        "n_trials": COUNT,
        "study_name": NAME,
        "out": PATH,
        "storage": TEXT.null(),
        # bounded: a timer of 1e12 s overflows in Optuna's heartbeat thread
        "heartbeat_s": whole(1, 86_400),
        "grace_s": whole(1, 7 * 86_400),
        "max_retry": whole(0),
    },
    "export": {
        "run": PATH,
        "out": TEXT.null(),
        "exports_dir": TEXT,
        "name": NAME.null(),
        "overwrite": FLAG,
        "opset": whole(17, 18),
        "debounce_k": COUNT.null(),
        "replay_max_frames": COUNT.null(),
        "choose_session": FLAG,
        "parity.score_eps": number(minimum=0.0).null(),
        "parity.atol": number(minimum=0.0),
        "parity.max_calls": COUNT.null(),
        "regression.threshold": number(),
        "session.rounds": COUNT,
        "session.max_frames": COUNT,
    },
    "compare": {
        "comparison.name": NAME,
        "seed": SEED,
        "runs_dir": TEXT,
        "out": TEXT.null(),
        "overwrite": FLAG,
        "progress": FLAG,
        "cost.export": FLAG,
        "cost.max_frames": COUNT,
        "cost.warmup": whole(0),
        "cost.keep_bundles": FLAG,
    },
    "closedloop": {
        "scenario": TEXT,
        "seeds": SEEDS,
        "train_seed": SEED,
        "trials_per_speed": whole(1, 1000).null(),
        "train_trials": whole(1, 10_000).null(),
        "warmup": whole(0),
        "runs_dir": TEXT,
        "out": TEXT.null(),
        "overwrite": FLAG,
    },
    "demo": {
        "out": PATH,
        "overwrite": FLAG,
        "seed": SEED,
        "quick": FLAG,
        "progress": FLAG,
        "cost.max_frames": COUNT,
        "cost.quick_max_frames": COUNT,
        "replay.max_frames": COUNT,
        "replay.warmup": whole(0),
    },
}


def _lookup(cfg: DictConfig, key: str) -> tuple[bool, bool, Any]:
    """(present, missing, value) of the dotted ``key``; interpolations resolved."""
    parent_key, _, leaf = key.rpartition(".")
    try:
        parent = OmegaConf.select(cfg, parent_key) if parent_key else cfg
        if not isinstance(parent, DictConfig) or leaf not in parent:
            return False, False, None
        if OmegaConf.is_missing(parent, leaf):
            return True, True, None
        return True, False, parent[leaf]
    except OmegaConfBaseException as exc:
        # e.g. `out=${nope}`: an interpolation the user wrote that cannot resolve.
        first = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise SlipkitError(f"{key}: {first}") from None


def check_value(key: str, value: Any, rule: Rule) -> None:
    """Raise a SlipkitError ``key=value: expected ...`` unless ``value`` meets ``rule``."""
    if value is None:
        if rule.nullable:
            return
        if rule.required:
            raise SlipkitError(f"{key}=...: missing; this option is required")
        raise SlipkitError(f"{key}=null: expected {rule.expected}")
    if not rule.accept(value):
        raise SlipkitError(f"{key}={show(value)}: expected {rule.expected}")


def check_rules(cfg: DictConfig, rules: Mapping[str, Rule], prefix: str = "") -> None:
    """Check every ``key -> rule`` of ``rules`` on ``cfg`` (keys relative to ``prefix``)."""
    for key, rule in rules.items():
        full = f"{prefix}{key}"
        present, missing, value = _lookup(cfg, full)
        if missing:
            raise SlipkitError(f"{full}=...: missing; this option is required")
        if not present:
            if rule.required:
                raise SlipkitError(f"{full}=...: missing; this option is required")
            continue
        check_value(full, value, rule)


def check_rates(
    cfg: DictConfig, node_key: str, *, nullable: bool, rule: Rule = RATE
) -> None:
    """Every ``*rate_hz`` option directly under ``node_key`` meets ``rule`` (default: a
    finite number > 0)."""
    present, missing, node = _lookup(cfg, node_key)
    if not present or missing or not isinstance(node, DictConfig):
        return
    rule = rule.null() if nullable else rule
    for key in map(str, node.keys()):
        if key.endswith("rate_hz"):
            check_rules(cfg, {f"{node_key}.{key}": rule})


def check_dataset(cfg: DictConfig, prefix: str = "") -> None:
    """The data options of a run (``dataset.*``, the scene's and the source's rates).

    ``dataset.n_trials`` and ``dataset.seed`` are read only when the run simulates
    (neither ``dataset.path`` nor ``dataset.raw`` is set), so only then are they checked.
    """
    check_rules(cfg, {"dataset.path": TEXT.null(), "dataset.raw": TEXT.null()}, prefix)
    _, _, path = _lookup(cfg, f"{prefix}dataset.path")
    _, _, raw = _lookup(cfg, f"{prefix}dataset.raw")
    if raw:
        check_rates(cfg, f"{prefix}source", nullable=True)
    if not path and not raw:
        check_rules(cfg, {"dataset.n_trials": COUNT, "dataset.seed": SEED}, prefix)
        check_rates(cfg, f"{prefix}scene.model", nullable=False, rule=SCENE_RATE)


def check_options(cfg: DictConfig, command: str) -> None:
    """Check the options of ``slipkit <command>``; raise a SlipkitError naming the first bad one."""
    check_rules(cfg, OPTIONS.get(command, {}))
    if command == "simulate":
        check_rates(cfg, "scene.model", nullable=False, rule=SCENE_RATE)
    elif command == "import":
        check_rates(cfg, "source", nullable=True)
    elif command == "train":
        check_dataset(cfg)
    elif command == "compare":
        check_dataset(cfg, "comparison.")


#: Hydra's instantiation keys: a node with a ``_target_`` may be given any of them.
_INSTANTIATE_KEYS = ("_target_", "_partial_", "_convert_", "_recursive_", "_args_")

#: subcommand -> mappings (dotted, ``*`` matching one key) that take new names although
#: their entries are plain values: the demo's ``scenario -> family`` style tables. A
#: mapping of mappings or lists (estimators, detectors, runs, effects, search
#: parameters) or an empty one (``task_overrides: {}``) takes new names anyway.
OPEN_MAPPINGS: dict[str, tuple[str, ...]] = {
    "demo": (
        "real",
        "real_comparisons",
        "closedloop.families",
        "closedloop.detector.*",
    ),
}


def _target_params(node: DictConfig) -> set[str] | None:
    """Keyword names ``node._target_`` takes; None: any (``**kwargs``) or not knowable here."""
    from hydra.utils import get_object

    try:
        target = get_object(str(node._get_node("_target_")._value()))  # type: ignore[union-attr]
        params = inspect.signature(target).parameters.values()
    except Exception:  # a target that does not load: instantiation says why
        return None
    if any(p.kind is inspect.Parameter.VAR_KEYWORD for p in params):
        return None
    return {
        p.name
        for p in params
        if p.kind
        in (inspect.Parameter.POSITIONAL_OR_KEYWORD, inspect.Parameter.KEYWORD_ONLY)
    }


def _effect_params(name: str) -> set[str] | None:
    """Keyword names of the scene effect behind effect key ``name``; None if not an effect."""
    from slipkit.sim.core import EFFECTS, _load_effect_modules, effect_name

    _load_effect_modules()
    effect = EFFECTS.get(effect_name(name))
    if effect is None:
        return None
    _, _, *params = inspect.signature(effect).parameters.values()  # state, rng, ...
    return {p.name for p in params}


def _takes(node: DictConfig, where: str, command: str) -> tuple[set[str], bool]:
    """(the keys ``node`` at dotted ``where`` takes, whether it takes any other key too)."""
    keys = {str(k) for k in node}
    if "_target_" in node:
        params = _target_params(node)
        return keys | (params or set()) | set(_INSTANTIATE_KEYS), params is None
    parent, _, leaf = where.rpartition(".")
    if parent == "effects" or parent.endswith(".effects"):
        params = _effect_params(leaf)
        if params is not None:
            return keys | params, False
    if any(fnmatch.fnmatchcase(where, p) for p in OPEN_MAPPINGS.get(command, ())):
        return keys, True
    raw = OmegaConf.to_container(node, resolve=False)
    values = list(raw.values()) if isinstance(raw, dict) else []
    named = [v for v in values if v is not None]
    # {} or a mapping of named entries (each a mapping or a list): a new name is an entry.
    return keys, not values or (
        bool(named) and all(isinstance(v, dict | list) for v in named)
    )


def _closest(word: str, candidates: list[str]) -> list[str]:
    """The candidates closest to ``word`` (difflib's ratio >= 0.6, within 0.1 of the best)."""
    close = difflib.get_close_matches(word, candidates, n=3, cutoff=0.6)
    scores = [difflib.SequenceMatcher(None, word, c).ratio() for c in close]
    return [c for c, r in zip(close, scores, strict=True) if r >= max(scores) - 0.1]


def unknown_key(cfg: DictConfig, key: str, command: str = "") -> str | None:
    """Why dotted ``key`` is not an option of ``cfg`` (one line, closest keys suggested); None if it is.

    A key is an option when ``cfg`` has it, when its node has a ``_target_`` whose
    callable takes it (or any keyword), when its node is a scene effect taking it,
    or when its node is a mapping of named entries (``estimators``, ``detectors``,
    ``search.params``, an empty ``{}``; :data:`OPEN_MAPPINGS`).
    """
    parts = key.split(".")
    node: Any = cfg
    for i, part in enumerate(parts):
        where = ".".join(parts[:i])
        here = where or "the config"
        if not isinstance(node, DictConfig):
            return f"{key}: unknown key; {here} is one value, not a group of options"
        keys, any_key = _takes(node, where, command)
        if part not in node:
            if any_key or part in keys:
                return None
            prefix = f"{where}." if where else ""
            shown = sorted(k for k in keys if not k.startswith("_"))
            close = _closest(part, shown)
            if close:
                hint = "did you mean " + " or ".join(prefix + c for c in close) + "?"
            else:
                more = ", ..." if len(shown) > 12 else ""
                hint = f"{here} has {', '.join(shown[:12])}{more}"
            return f"{key}: unknown key; {hint}"
        try:
            node = node._get_node(part)
        except OmegaConfBaseException:
            return None
        if not isinstance(node, DictConfig) or node._is_none():
            node = None
    return None


__all__ = [
    "OPEN_MAPPINGS",
    "OPTIONS",
    "Rule",
    "check_dataset",
    "check_options",
    "check_rules",
    "check_value",
    "show",
    "unknown_key",
    "within",
]


def one_line(text: str) -> str:
    """``text`` on one line: its non-blank lines joined with ``; `` (tabs and indents dropped)."""
    parts = [" ".join(line.split()) for line in str(text).splitlines()]
    parts = [p for p in parts if p]
    # "Could not override 'x'." + "Key 'x' is not in struct" -> "...'x'; Key ..."
    head = [p.rstrip(".:") for p in parts[:-1]]
    return "; ".join([*head, *parts[-1:]]) or "(no message)"


def composition_message(exc: Exception) -> str:
    """One line for an error Hydra or OmegaConf raised while composing the config."""
    from hydra.errors import MissingConfigException, OverrideParseException

    if isinstance(exc, MissingConfigException) and exc.options:
        first = str(exc).splitlines()[0]
        return f"{first}; available: {', '.join(map(str, exc.options))}"
    if isinstance(exc, OverrideParseException):
        return f"{exc.override}: {exc.message}"
    text = str(exc)
    cause = exc.__cause__
    if cause is not None and str(cause) and str(cause) not in text:
        text = f"{text}\n{cause}"
    return text
