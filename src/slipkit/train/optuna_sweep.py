"""``slipkit sweep``: one Optuna study over ``slipkit train`` runs, shared by any workers.

``slipkit sweep experiment=<name> search=<space> [train overrides]`` composes
``configs/sweep.yaml``: the train config plus the sweep's options. The search space is
config (``configs/search/<space>.yaml``)::

    params:
      model:
        C:      {type: float, low: 1.0, high: 1.0e4, log: true}
        kernel: {type: categorical, choices: [rbf, linear]}
      task:
        n_slip: {type: int, low: 2, high: 8}

(nested, so ``search.params.model.C.high=100`` overrides a bound; dotted keys such as
``model.C: {...}`` work too).
Each trial is one ``slipkit train`` run: ``configs/train.yaml`` composed by Hydra with
the command line's train overrides (``experiment=<name>``, ``dataset.n_trials=6``, ...)
and the trial's parameters as overrides, trained by
:func:`slipkit.train.commands.train_main` into its own run folder
``<out>/trials/<number>`` (written atomically). The study optimises the task's
objective, a validation score on the training side, so the best run is chosen without
looking at test data.

The study lives in an Optuna storage: ``sqlite:///<out>/study.db`` by default, any
RDB URL with ``storage=`` (``postgresql://user@host/db``). Before anything is created,
``out`` must be new, empty or a sweep's own folder (:data:`LAYOUT`: ``study.db``,
``trials/``, ``best.json``), outside every dataset, run and bundle and outside the
trials' data; an SQLite file must be new or an Optuna database, outside every dataset,
run and bundle. An in-memory SQLite storage (``sqlite://``) is refused: the heartbeat
thread and the other workers cannot reach it, and the study would end with the worker. Every worker started with
the same ``study_name`` and storage joins the study (``load_if_exists``), on this
machine or another; together they run ``n_trials`` complete trials. A worker that
dies mid-trial stops its heartbeat; after ``grace_s`` the next worker marks that
trial failed and Optuna's :class:`~optuna.storages.RetryHeartbeatStaleTrialCallback`
puts its parameters back in the queue, so a killed study resumes where it stopped.
Every trial records its run folder, worker (host:pid), overrides and validation score as user
attributes; the best run is printed last and written to ``<out>/best.json``.
"""

from __future__ import annotations

import contextlib
import datetime as dt
import inspect
import json
import logging
import math
import os
import re
import socket
import sqlite3
import stat
import time
import warnings
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from omegaconf import DictConfig, OmegaConf

from slipkit._files import (
    Layout,
    check_out_file,
    check_out_path,
    check_plain_name,
    check_writable,
    read_json_object,
    write_out_file,
)
from slipkit.errors import SlipkitError

log = logging.getLogger("slipkit.sweep")

#: the search space's parameter types -> the fields each one takes (required, optional)
SPACE_FIELDS: dict[str, tuple[frozenset[str], frozenset[str]]] = {
    "float": (frozenset({"low", "high"}), frozenset({"log", "step"})),
    "int": (frozenset({"low", "high"}), frozenset({"log", "step"})),
    "categorical": (frozenset({"choices"}), frozenset()),
}
#: the trial folders under ``out``; trial ``k`` trains into ``<out>/trials/<k:04d>``
TRIALS_DIR = "trials"
BEST_FILE = "best.json"
#: the default storage, ``sqlite:///<out>/study.db``
STUDY_FILE = "study.db"
#: the first 16 bytes of every SQLite database file
SQLITE_HEADER = b"SQLite format 3\x00"


def sqlite_tables(path: Path | str) -> set[str] | None:
    """The table names of the SQLite database file ``path`` (an empty file: none);
    None when ``path`` is not a regular file holding an SQLite database.

    Read through a read-only connection (``mode=ro``): the check writes nothing.
    """
    try:
        st = os.stat(path)
        if not stat.S_ISREG(st.st_mode):
            return None
        if st.st_size == 0:
            return set()  # created by another worker a moment ago, not yet written
        with open(path, "rb") as fh:
            if fh.read(len(SQLITE_HEADER)) != SQLITE_HEADER:
                return None
        uri = f"{Path(path).resolve().as_uri()}?mode=ro"
        con = sqlite3.connect(uri, uri=True, timeout=60)
        try:
            rows = con.execute(
                "SELECT name FROM sqlite_master WHERE type = 'table'"
            ).fetchall()
        finally:
            con.close()
    except (OSError, sqlite3.Error):
        return None
    return {str(r[0]) for r in rows}


def is_study_db(path: Path) -> bool:
    """An SQLite file Optuna may write: an Optuna database (table ``studies``), or one
    without tables yet (another worker is creating it)."""
    tables = sqlite_tables(path)
    return tables is not None and (not tables or "studies" in tables)


def _is_best(path: Path) -> bool:
    """A ``best.json`` a sweep wrote (``study_name``, ``trial`` and ``run_dir``)."""
    obj = read_json_object(path)
    return obj is not None and {"study_name", "trial", "run_dir"} <= obj.keys()


#: What a sweep writes into ``out``, and nothing else: an existing ``out`` holding only
#: these is a sweep's folder, which later workers join and a re-run resumes.
LAYOUT = Layout(
    "sweep",
    frozenset(
        {STUDY_FILE, *(STUDY_FILE + side for side in ("-journal", "-wal", "-shm"))}
        | {TRIALS_DIR, BEST_FILE}
    ),
    marks={STUDY_FILE: is_study_db, TRIALS_DIR: Path.is_dir, BEST_FILE: _is_best},
)
#: the sweep's own options (configs/sweep.yaml); every other override goes to each trial
SWEEP_KEYS = frozenset(
    {"search", "n_trials", "study_name", "out", "storage", "heartbeat_s", "grace_s"}
    | {"max_retry"}
)
#: tries at opening a storage that other workers may be creating at the same moment
_OPEN_ATTEMPTS = 5
#: a worker stops after this many of its trials in a row gave no finite objective
MAX_FAILED_IN_A_ROW = 3
#: user attribute ``host:pid`` of the worker running a trial, set at its first heartbeat
WORKER = "worker"
#: user attribute of a trial that was asked for but not run (the study was full)
NOT_RUN = "not_run"


# -- the search space ---------------------------------------------------------------------
def _number(where: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise SlipkitError(f"{where}={value}: expected a number")
    if not math.isfinite(value):
        raise SlipkitError(f"{where}={value}: expected a finite number")
    return value


def _scalar(where: str, value: Any) -> Any:
    if value is None or isinstance(value, str | int | float | bool):
        return value
    raise SlipkitError(
        f"{where}: a choice must be a text, number, true, false or null; got {value}"
    )


def _leaves(node: Mapping[str, Any], prefix: str = "") -> Iterator[tuple[str, Any]]:
    """(dotted key, spec) of a space written nested (``model: {C: {type: ...}}``, which
    ``search.params.model.C.high=100`` can override) or dotted (``model.C: {...}``).
    A spec is the mapping holding a text ``type``; any other mapping is a level."""
    for key, value in node.items():
        dotted = f"{prefix}{key}"
        if (
            isinstance(value, Mapping)
            and value
            and not isinstance(value.get("type"), str)
        ):
            if "type" in value:  # {type: null}, {type: 3}: a spec with a bad type
                yield dotted, value
            else:
                yield from _leaves(value, f"{dotted}.")
        else:
            yield dotted, value


def read_space(node: Any, where: str = "search.params") -> dict[str, Any]:
    """The search space of ``node`` (``{key: {type: ..., ...}}``) as Optuna distributions.

    Parameters
    ----------
    node : mapping
        ``search.params`` of the sweep config: train-config key (nested or dotted)
        -> spec.
    where : str
        The config path named in error messages.

    Returns
    -------
    dict
        ``{key: optuna.distributions.BaseDistribution}`` in the config's order.

    Raises
    ------
    SlipkitError
        One line naming the parameter and field at fault (unknown type, a missing or
        unknown field, ``low >= high``, a log scale with ``low <= 0``, no choices).
    """
    from optuna.distributions import (
        CategoricalDistribution,
        FloatDistribution,
        IntDistribution,
    )

    if isinstance(node, DictConfig):
        node = OmegaConf.to_container(node, resolve=True)
    if not isinstance(node, Mapping) or not node:
        raise SlipkitError(
            f"{where}: expected a mapping of train-config keys to parameter specs, "
            f"e.g. {{model.C: {{type: float, low: 1, high: 1e4, log: true}}}}; got {node}"
        )
    space: dict[str, Any] = {}
    for key, spec in _leaves(node):
        at = f"{where}.{key}"
        if not isinstance(spec, Mapping):
            raise SlipkitError(f"{at}: expected {{type: float|int|categorical, ...}}")
        kind = spec.get("type")
        if kind not in SPACE_FIELDS:
            raise SlipkitError(
                f"{at}.type={kind}: expected one of {', '.join(SPACE_FIELDS)}"
            )
        required, optional = SPACE_FIELDS[kind]
        missing = sorted(required - set(spec))
        unknown = sorted(set(spec) - required - optional - {"type"})
        if missing:
            raise SlipkitError(f"{at}: a {kind} parameter needs {', '.join(missing)}")
        if unknown:
            raise SlipkitError(
                f"{at}.{unknown[0]}: not a field of a {kind} parameter; fields: "
                f"{', '.join(sorted(required | optional))}"
            )
        try:
            if kind == "categorical":
                choices = spec["choices"]
                if not isinstance(choices, list | tuple) or not choices:
                    raise SlipkitError(f"{at}.choices: expected a non-empty list")
                values = [_scalar(f"{at}.choices", c) for c in choices]
                space[str(key)] = CategoricalDistribution(values)
                continue
            low = _number(f"{at}.low", spec["low"])
            high = _number(f"{at}.high", spec["high"])
            log_scale = spec.get("log", False)
            if not isinstance(log_scale, bool):
                raise SlipkitError(f"{at}.log={log_scale}: expected true or false")
            step = spec.get("step")
            if step is not None:
                step = _number(f"{at}.step", step)
            if not low < high:
                raise SlipkitError(f"{at}: low={low} must be below high={high}")
            if kind == "int":
                if not (float(low).is_integer() and float(high).is_integer()):
                    raise SlipkitError(
                        f"{at}: an int parameter needs whole low and high"
                    )
                space[str(key)] = IntDistribution(
                    int(low), int(high), log=log_scale, step=int(step or 1)
                )
            else:
                space[str(key)] = FloatDistribution(
                    float(low), float(high), log=log_scale, step=step
                )
        except ValueError as exc:  # Optuna's own checks (log with low <= 0, step)
            raise SlipkitError(f"{at}: {exc}") from None
    return space


def suggest(trial: Any, key: str, dist: Any) -> Any:
    """``trial.suggest_*`` for one distribution of :func:`read_space`."""
    from optuna.distributions import CategoricalDistribution, IntDistribution

    if isinstance(dist, CategoricalDistribution):
        return trial.suggest_categorical(key, list(dist.choices))
    if isinstance(dist, IntDistribution):
        return trial.suggest_int(key, dist.low, dist.high, step=dist.step, log=dist.log)
    return trial.suggest_float(key, dist.low, dist.high, step=dist.step, log=dist.log)


_PLAIN = re.compile(r"[A-Za-z_][\w.\-/]*\Z")


def override(key: str, value: Any) -> str:
    """``key=value`` as Hydra parses it back to ``value`` (floats in full, text quoted)."""
    if value is None:
        text = "null"
    elif isinstance(value, bool):
        text = "true" if value else "false"
    elif isinstance(value, float):
        text = repr(value)  # shortest text that reads back as the same float
    elif isinstance(value, int) or (
        _PLAIN.match(str(value)) and str(value) not in {"true", "false", "null"}
    ):
        text = str(value)
    else:
        text = "'" + str(value).replace("\\", "\\\\").replace("'", "\\'") + "'"
    return f"{key}={text}"


# -- composing the train config of a trial ------------------------------------------------
@contextlib.contextmanager
def _hydra_context() -> Iterator[None]:
    """Hydra's config search path: the running app's (``slipkit sweep``) or slipkit's own."""
    from hydra import initialize_config_dir
    from hydra.core.global_hydra import GlobalHydra

    if GlobalHydra.instance().is_initialized():
        yield
        return
    from slipkit import config_dir

    with initialize_config_dir(config_dir=str(config_dir()), version_base="1.3"):
        yield


def compose_train(overrides: Sequence[str]) -> DictConfig:
    """``configs/train.yaml`` composed with ``overrides``, as ``slipkit train`` would.

    Raises
    ------
    SlipkitError
        The overrides do not compose (unknown experiment or key), in one line.
    """
    from hydra import compose
    from hydra.errors import HydraException, MissingConfigException
    from omegaconf.errors import OmegaConfBaseException

    try:
        with _hydra_context():
            return compose(config_name="train", overrides=list(overrides))
    except MissingConfigException as exc:
        first = str(exc).splitlines()[0]
        options = (
            f"; available: {', '.join(map(str, exc.options))}" if exc.options else ""
        )
        raise SlipkitError(f"train config: {first}{options}") from None
    except (HydraException, OmegaConfBaseException) as exc:
        text = " ".join(str(exc).split())
        cause = exc.__cause__
        if cause is not None and str(cause) not in text:
            text = f"{text}; {' '.join(str(cause).split())}"
        raise SlipkitError(f"train config with {list(overrides)}: {text}") from None


# -- the study ----------------------------------------------------------------------------
@dataclass(frozen=True)
class Objective:
    """What the study optimises: the task's validation objective."""

    name: str
    direction: str


def _objective_of(cfg: DictConfig) -> Objective:
    from slipkit.train.commands import build

    task = build(cfg.task, "task")
    name, direction = str(task.objective), str(task.direction)
    if not name.startswith("validation."):
        # The no-leak rule: a run is chosen on its validation score, never on test.
        raise SlipkitError(
            f"task {cfg.task._target_}: objective {name!r} is not a validation score; "
            "a sweep selects runs on validation only"
        )
    return Objective(name, direction)


def _sampler_class() -> Any:
    """A TPE sampler whose proposal for trial ``k`` is seeded by ``(seed, k)``.

    Optuna seeds a sampler per process: two workers given the same seed would propose
    the same parameters in lockstep. Seeding per trial number (unique in a study)
    keeps one worker's study reproducible and several workers' proposals distinct.
    Written here because Optuna has no per-trial seed; it uses only the public
    :class:`~optuna.samplers.BaseSampler` interface, delegating to a fresh
    :class:`~optuna.samplers.TPESampler` per trial.
    """
    import optuna

    class TrialSeededTPE(optuna.samplers.BaseSampler):
        def __init__(self, seed: int) -> None:
            self.seed = int(seed)
            self._inner = optuna.samplers.TPESampler(seed=self.seed)

        def _for(self, number: int) -> optuna.samplers.TPESampler:
            state = np.random.SeedSequence([self.seed, number]).generate_state(1)
            return optuna.samplers.TPESampler(seed=int(state[0]))

        def before_trial(self, study: Any, trial: Any) -> None:
            self._inner = self._for(trial.number)
            self._inner.before_trial(study, trial)

        def infer_relative_search_space(self, study: Any, trial: Any) -> Any:
            return self._inner.infer_relative_search_space(study, trial)

        def sample_relative(self, study: Any, trial: Any, search_space: Any) -> Any:
            return self._inner.sample_relative(study, trial, search_space)

        def sample_independent(
            self, study: Any, trial: Any, name: str, distribution: Any
        ) -> Any:
            return self._inner.sample_independent(study, trial, name, distribution)

        def after_trial(self, study: Any, trial: Any, state: Any, values: Any) -> None:
            self._inner.after_trial(study, trial, state, values)

        def reseed_rng(self) -> None:
            self._inner.reseed_rng()

    return TrialSeededTPE


def storage_url(storage: Any, out: Path) -> str:
    """The study's storage: ``storage`` if given, else ``sqlite:///<out>/study.db``."""
    if storage:
        return str(storage)
    return f"sqlite:///{(out / STUDY_FILE).resolve()}"


def sqlite_path(url: str) -> Path | None:
    """The database file of an SQLite ``url``; None for any other database.

    Raises
    ------
    SlipkitError
        ``storage=...``: an in-memory database (``sqlite://``, ``:memory:``,
        ``mode=memory``): it lives only in this worker's connection, so Optuna's
        heartbeat thread and the other workers cannot reach it and the study ends with
        the worker; or a database opened read-only (``mode=ro``, ``immutable``).
    """
    if not url.startswith("sqlite"):
        return None
    from sqlalchemy.engine import make_url
    from sqlalchemy.exc import ArgumentError

    try:
        parsed = make_url(url)
    except ArgumentError:
        return None  # open_storage names it
    where = f"storage={url}"  # as given: an SQLite URL holds no password
    query = {k: str(v).lower() for k, v in parsed.query.items()}
    db = parsed.database or ""
    if query.get("uri") in {"true", "1"} and db.startswith("file:"):
        db = db[len("file:") :]
    if db in {"", ":memory:"} or query.get("mode") == "memory":
        raise SlipkitError(
            f"{where}: an in-memory database lives only in this worker's connection "
            "(the heartbeat thread and other workers cannot reach it, and the study "
            "ends with the worker); give a file, sqlite:///<path>, or leave storage "
            "unset for <out>/study.db"
        )
    if query.get("mode") == "ro" or query.get("immutable") in {"1", "true"}:
        raise SlipkitError(
            f"{where}: opened read-only; a sweep writes its trials into the study"
        )
    return Path(db)


def check_storage(url: str, inputs: Mapping[str, Any]) -> Path | None:
    """Refuse an SQLite storage whose file could destroy data; its path (None: no file).

    The file follows the single-output-file rule (:func:`slipkit._files.check_out_file`:
    not an input, a folder, a link or a device, not inside a dataset, run or bundle);
    an existing file must be an Optuna database (:func:`is_study_db`) that this
    account may write.
    """
    path = sqlite_path(url)
    if path is None:
        return None
    check_out_file(
        path,
        option="storage",
        inputs=inputs,
        is_own=is_study_db,
        what="an Optuna study database (SQLite)",
    )
    if path.exists() and not os.access(path, os.W_OK):
        raise SlipkitError(
            f"storage={path}: the database file is read-only; a sweep writes its "
            "trials into it"
        )
    return path


def shown_url(url: str) -> str:
    """``url`` with any password hidden (for printing)."""
    with contextlib.suppress(Exception):
        from sqlalchemy.engine import make_url

        return make_url(url).render_as_string(hide_password=True)
    return url


def open_storage(url: str, *, heartbeat_s: int, grace_s: int, max_retry: int) -> Any:
    """An Optuna RDB storage with heartbeats whose dead workers' trials are retried.

    A trial whose heartbeat stops for ``grace_s`` (its worker died) is failed by the
    next worker, and the callback queues its parameters again (at most ``max_retry``
    times per trial).

    Raises
    ------
    SlipkitError
        ``storage=...``: not a database URL, or the database cannot be reached.
    """
    import optuna
    from sqlalchemy.exc import (
        ArgumentError,
        IntegrityError,
        OperationalError,
        SQLAlchemyError,
    )

    callback_cls = (
        getattr(optuna.storages, "RetryHeartbeatStaleTrialCallback", None)
        or optuna.storages.RetryFailedTrialCallback
    )  # optuna < 4.9
    params = inspect.signature(optuna.storages.RDBStorage).parameters
    callback_key = (
        "heartbeat_stale_trial_callback"
        if "heartbeat_stale_trial_callback" in params
        else "failed_trial_callback"
    )
    # SQLite locks the whole file per write: wait for the other workers (s) rather
    # than fail with "database is locked".
    engine = {"connect_args": {"timeout": 60}} if url.startswith("sqlite") else None
    with warnings.catch_warnings():  # experimental since 2.8, still in 5.0
        warnings.simplefilter("ignore", optuna.exceptions.ExperimentalWarning)
        retry = callback_cls(max_retry=int(max_retry))
    callback: dict[str, Any] = {callback_key: retry}
    try:
        for attempt in range(_OPEN_ATTEMPTS):
            try:
                with warnings.catch_warnings():
                    warnings.simplefilter(
                        "ignore", optuna.exceptions.ExperimentalWarning
                    )
                    storage = optuna.storages.RDBStorage(
                        url,
                        engine_kwargs=engine,
                        heartbeat_interval=int(heartbeat_s),
                        grace_period=int(grace_s),
                        **callback,
                    )
                    return storage
            except (IntegrityError, OperationalError):
                # Workers started together on a new database race to create its
                # tables (alembic_version UNIQUE); the loser finds them made on a retry.
                if attempt == _OPEN_ATTEMPTS - 1:
                    raise
                time.sleep(0.5 * (attempt + 1))
        raise AssertionError("unreachable")  # pragma: no cover
    except ArgumentError as exc:
        raise SlipkitError(
            f"storage={shown_url(url)}: not a database URL "
            f"(e.g. sqlite:///study.db, postgresql://user@host/db): {exc}"
        ) from None
    except (SQLAlchemyError, ImportError, OSError) as exc:
        first = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        hint = (
            " (postgresql:// needs `pip install 'psycopg[binary]'`; "
            "postgresql+psycopg2:// psycopg2, mysql+pymysql:// PyMySQL)"
            if isinstance(exc, ImportError)
            else ""
        )
        raise SlipkitError(
            f"storage={shown_url(url)}: cannot open: {first}{hint}"
        ) from None


class _NotRun(Exception):
    """A trial asked for after the study had its trials (another worker was faster)."""


class _NoScore(Exception):
    """A trial's run gave no finite objective (the trial fails, the study goes on)."""


def _held(study: Any, trial: Any) -> int:
    """Trials that count against ``n_trials`` before ``trial``: every complete one,
    and every running or queued one with a lower number. Trial numbers are handed out
    by the storage, so racing workers agree on which of them came first."""
    from optuna.trial import TrialState

    held = 0
    for t in study.get_trials(deepcopy=False):
        if t.state == TrialState.COMPLETE or (
            t.number < trial.number
            and t.state in (TrialState.RUNNING, TrialState.WAITING)
        ):
            held += 1
    return held


def _fail_stale(study: Any, storage: Any, grace_s: float) -> None:
    """Fail the trials of dead workers so that their parameters are run again.

    Optuna fails a running trial whose heartbeat is older than ``grace_s``
    (``fail_stale_trials``) and the storage's retry callback queues its parameters. A worker killed
    between asking for a trial and its first heartbeat leaves a running trial with
    no heartbeat at all, which Optuna never finds stale: such a trial (no
    :data:`WORKER` attribute, started more than ``grace_s`` ago) is failed here, and
    its queued parameters, if it had any, are queued again.
    """
    import optuna
    from optuna.trial import TrialState

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", optuna.exceptions.ExperimentalWarning)
        optuna.storages.fail_stale_trials(study)
    now = dt.datetime.now()
    study_id = storage.get_study_id_from_name(study.study_name)
    for t in study.get_trials(deepcopy=False, states=(TrialState.RUNNING,)):
        if WORKER in t.user_attrs or t.datetime_start is None:
            continue
        if (now - t.datetime_start).total_seconds() <= grace_s:
            continue
        trial_id = storage.get_trial_id_from_study_id_trial_number(study_id, t.number)
        try:
            if not storage.set_trial_state_values(trial_id, state=TrialState.FAIL):
                continue
        except optuna.exceptions.UpdateFinishedTrialError:
            continue  # another worker failed it first
        fixed = t.system_attrs.get("fixed_params")
        if fixed:
            study.enqueue_trial(dict(fixed), user_attrs={"retry_of": t.number})


def _study_identity(
    overrides: Sequence[str], space: Mapping[str, Any], obj: Objective
) -> dict[str, Any]:
    from optuna.distributions import distribution_to_json

    return {
        "train_overrides": sorted(overrides),  # the same set in any order
        "space": {k: json.loads(distribution_to_json(d)) for k, d in space.items()},
        "objective": obj.name,
        "direction": obj.direction,
    }


def _check_joins(study: Any, identity: Mapping[str, Any], name: str, url: str) -> None:
    """Set the study's identity on creation; refuse a worker whose sweep differs."""
    stored = study.user_attrs.get("slipkit_sweep")
    if stored is None:
        study.set_user_attr("slipkit_sweep", dict(identity))
        return
    for key, value in identity.items():
        if stored.get(key) != value:
            raise SlipkitError(
                f"study_name={name}: the study in {shown_url(url)} was started with "
                f"{key}={stored.get(key)}, this worker has {key}={value}; workers of "
                "one study run the same sweep (or pick another study_name)"
            )


def train_overrides(task_overrides: Sequence[str]) -> list[str]:
    """The command line's train overrides: all but the sweep's own options."""
    kept = []
    for item in task_overrides:
        key = str(item).split("=", 1)[0].lstrip("+~")
        if key.split(".", 1)[0] not in SWEEP_KEYS:
            kept.append(str(item))
    return kept


def best_lines(study: Any, obj: Objective, url: str) -> list[str]:
    """What a finished worker prints: the study and its best run (by validation)."""
    from optuna.trial import TrialState

    best = study.best_trial
    done = len(study.get_trials(deepcopy=False, states=(TrialState.COMPLETE,)))
    params = ", ".join(override(k, v) for k, v in best.params.items())
    return [
        f"study {study.study_name} ({shown_url(url)}): {done} complete trials",
        f"sweep best (by {obj.name}, {obj.direction}, validation on the training "
        f"side): {best.value:.6g} -- trial {best.number}",
        f"  parameters: {params}",
        f"  run: {best.user_attrs.get('run_dir')}",
    ]


def sweep_main(
    cfg: DictConfig, overrides: Sequence[str] | None = None
) -> dict[str, Any]:
    """Join (or start) the study ``cfg.study_name`` and run trials until it holds
    ``cfg.n_trials`` complete ones; print and return the best.

    Parameters
    ----------
    cfg : DictConfig
        ``configs/sweep.yaml`` composed: the train config, ``search`` and the sweep's
        options.
    overrides : list of str, optional
        The command line's overrides (default: Hydra's, of the running
        ``slipkit sweep``); all but the sweep's own options go to every trial.

    Returns
    -------
    dict
        The best trial: ``trial``, ``params``, ``run_dir``, ``objective``.
    """
    import optuna
    from hydra.core.hydra_config import HydraConfig
    from optuna.trial import TrialState

    from slipkit._options import check_options
    from slipkit.train.commands import train_main

    if overrides is None:
        overrides = (
            list(HydraConfig.get().overrides.task) if HydraConfig.initialized() else []
        )
    check_options(cfg, "train")
    out = Path(str(cfg.out))
    url = storage_url(cfg.get("storage"), out)
    given = bool(cfg.get("storage"))
    # Checked first and before anything is created: the trials read their data, the
    # sweep writes only its own folder and its own database.
    inputs = {
        "dataset.path": cfg.dataset.get("path"),
        "dataset.raw": cfg.dataset.get("raw"),
    }
    check_out_path(out, inputs=inputs, layout=LAYOUT, overwrite=True)
    db = check_storage(url, inputs) if given else None
    space = read_space(cfg.search.get("params"))
    fixed = train_overrides(overrides)
    base = compose_train(fixed)
    absent = object()
    for key in space:
        # A key the train config lacks would fail in every trial: refuse it first.
        if OmegaConf.select(base, key, default=absent) is absent:
            raise SlipkitError(
                f"search.params.{key}: the train config (overrides {fixed}) has no "
                f"{key!r} to search"
            )
    obj = _objective_of(base)
    n_trials = int(cfg.n_trials)
    if int(cfg.grace_s) <= int(cfg.heartbeat_s):
        raise SlipkitError(
            f"grace_s={cfg.grace_s}: must exceed heartbeat_s={cfg.heartbeat_s} (a live "
            "worker's trial would look dead between two heartbeats)"
        )
    name = check_plain_name(str(cfg.study_name), option="study_name")
    sqlite = url.startswith("sqlite")
    if sqlite:  # the database file is made when the storage opens: out first
        _make_out(out)
        if not given:  # <out>/study.db: checked once out is known to be a folder
            db = check_storage(url, inputs)
        if db is not None and db.parent.resolve() != out.resolve():
            check_writable(db.parent, option="storage")
    storage = open_storage(
        url,
        heartbeat_s=int(cfg.heartbeat_s),
        grace_s=int(cfg.grace_s),
        max_retry=int(cfg.max_retry),
    )
    if not sqlite:  # a server database: out once the storage is known to open
        _make_out(out)
    # ERROR: a trial that fails raises through to the CLI's one line anyway.
    optuna.logging.set_verbosity(optuna.logging.ERROR)
    study = _joined_study(
        storage, name, url, obj, int(base.seed), _study_identity(fixed, space, obj)
    )
    host = socket.gethostname()
    print(f"study {name} ({shown_url(url)}): worker {host}:{os.getpid()} joined")

    study_id = storage.get_study_id_from_name(name)
    failed: list[int] = []  # this worker's trials in a row without a finite score

    def objective(trial: Any) -> float:
        # The first heartbeat now, not when Optuna's heartbeat thread gets to it: from
        # here on a dead worker's trial is found stale and its parameters retried.
        storage.record_heartbeat(
            storage.get_trial_id_from_study_id_trial_number(study_id, trial.number)
        )
        trial.set_user_attr(WORKER, f"{host}:{os.getpid()}")
        params = {key: suggest(trial, key, dist) for key, dist in space.items()}
        if _held(study, trial) >= n_trials:
            trial.set_user_attr(NOT_RUN, "the study already held n_trials trials")
            raise _NotRun
        changed = [override(key, value) for key, value in params.items()]
        run_dir = (out / TRIALS_DIR / f"{trial.number:04d}").resolve()
        trial.set_user_attr("run_dir", str(run_dir))
        trial.set_user_attr("overrides", changed)
        train_cfg = compose_train([*fixed, *changed])
        train_cfg.run_dir = str(run_dir)
        check_options(train_cfg, "train")
        print(f"trial {trial.number}: {' '.join(changed)}")
        value = float(train_main(train_cfg))
        trial.set_user_attr("objective", obj.name)
        trial.set_user_attr("validation_score", value)
        if not math.isfinite(value):
            failed.append(trial.number)
            raise _NoScore(f"{obj.name} = {value} (run folder {run_dir})")
        failed.clear()
        return value

    poll_s = max(0.2, min(float(cfg.heartbeat_s), 5.0))
    waiting_said = False
    while True:
        _fail_stale(study, storage, float(cfg.grace_s))
        trials = study.get_trials(deepcopy=False)
        complete = sum(t.state == TrialState.COMPLETE for t in trials)
        running = sum(t.state == TrialState.RUNNING for t in trials)
        if complete >= n_trials:
            break
        if complete + running >= n_trials:
            # The rest are running in other workers: wait for them to finish, or to go
            # stale (a dead worker) and come back as queued retries.
            if not waiting_said:
                print(f"waiting for {running} running trial(s) of other workers")
                waiting_said = True
            time.sleep(poll_s)
            continue
        waiting_said = False
        try:
            study.optimize(
                objective, n_trials=1, catch=(_NotRun, _NoScore), gc_after_trial=False
            )
        except optuna.exceptions.UpdateFinishedTrialError as exc:
            # Another worker took this live trial for dead (no heartbeat for grace_s:
            # a stalled machine or network) and queued its parameters again; the
            # retry counts, this result stays in its run folder only.
            log.warning("a trial was failed by another worker meanwhile: %s", exc)
        if len(failed) >= MAX_FAILED_IN_A_ROW:
            # Optuna fails a trial without a finite value and goes on; a config whose
            # every run scores NaN would go on for ever.
            raise SlipkitError(
                f"study {name}: trials {failed} in a row gave no finite {obj.name}; "
                f"see their train.log under {out / TRIALS_DIR}"
            )

    for line in best_lines(study, obj, url):
        print(line)
    best = study.best_trial
    record = {
        "study_name": name,
        "storage": shown_url(url),
        "objective": {
            "name": obj.name,
            "direction": obj.direction,
            "value": best.value,
        },
        "trial": best.number,
        "params": best.params,
        "run_dir": best.user_attrs.get("run_dir"),
        "worker": best.user_attrs.get(WORKER),
        "n_complete": sum(
            t.state == TrialState.COMPLETE for t in study.get_trials(deepcopy=False)
        ),
    }
    write_out_file(
        out / BEST_FILE,
        json.dumps(record, indent=2) + "\n",
        option="out",
        is_own=_is_best,
        what="a sweep's best.json",
    )
    print(out / BEST_FILE)
    return record


def _make_out(out: Path) -> None:
    """Create ``out`` (checked by :data:`LAYOUT` already) and check it can be written."""
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise SlipkitError(
            f"out={out}: cannot create it: {exc.strerror or exc}"
        ) from None
    check_writable(out, option="out")


def _joined_study(
    storage: Any,
    name: str,
    url: str,
    obj: Objective,
    seed: int,
    identity: Mapping[str, Any],
) -> Any:
    """``optuna.create_study(load_if_exists=True)`` and :func:`_check_joins`; a database
    that refuses the write (read-only, locked) is a :class:`SlipkitError` naming
    ``storage``."""
    import optuna
    from optuna.study import StudyDirection
    from sqlalchemy.exc import OperationalError

    try:
        study = optuna.create_study(
            storage=storage,
            study_name=name,
            direction=StudyDirection[obj.direction.upper()],
            sampler=_sampler_class()(seed),
            load_if_exists=True,
        )
        _check_joins(study, identity, name, url)
        return study
    except (OperationalError, optuna.exceptions.StorageInternalError) as exc:
        # Optuna wraps a failed commit; the database's own reason is its cause
        cause = exc.__cause__ or exc
        cause = getattr(cause, "orig", None) or cause
        first = (str(cause) or type(cause).__name__).splitlines()[0]
        raise SlipkitError(
            f"storage={shown_url(url)}: cannot write the study: {first}"
        ) from None


__all__ = [
    "BEST_FILE",
    "LAYOUT",
    "SPACE_FIELDS",
    "STUDY_FILE",
    "SWEEP_KEYS",
    "TRIALS_DIR",
    "Objective",
    "best_lines",
    "check_storage",
    "compose_train",
    "is_study_db",
    "open_storage",
    "override",
    "read_space",
    "sqlite_path",
    "sqlite_tables",
    "storage_url",
    "suggest",
    "sweep_main",
    "train_overrides",
]
