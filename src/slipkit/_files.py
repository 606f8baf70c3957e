"""Checksums and all-or-nothing writes, shared by datasets, run folders and bundles.

Standard library only (plus :mod:`slipkit.errors`), so the gripper-PC runtime can use it
without pandas or pyarrow. Written by hand because the standard library already has the
two primitives that matter (``os.replace`` is atomic within one filesystem, ``hashlib``);
a dependency would add nothing.

Every command that writes goes through two guards here (``docs/robustness.md``,
"Writes that could lose data"):

* :func:`check_out_path` (called by the command before any work, naming its option):
  ``out`` must not be, hold or sit inside one of the command's inputs, must not sit
  inside another slipkit folder (dataset, run, bundle), and may replace an existing
  folder only with ``overwrite`` and only when that folder is of the same kind
  (recognised by its manifest, :func:`folder_kind`);
* :func:`atomic_dir` (the write itself) checks the same target rules again, restores
  or reports what an interrupted earlier write left behind, and never leaves the name
  empty: an overwrite that fails between its two renames puts the old folder back.

Options naming one file (``slipkit-run --json``, a sweep's ``best.json``, an SQLite
study) go through :func:`check_out_file` before any work and :func:`write_out_file` at
the write: never an input, a folder, a symlink, a FIFO, a device or a socket, never
inside a dataset, run or bundle, and an existing file only when it is recognisably what
the command writes there.
"""

from __future__ import annotations

import contextlib
import glob
import hashlib
import json
import logging
import os
import shutil
import stat
import tempfile
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path

from slipkit.errors import SlipkitError

log = logging.getLogger("slipkit.files")

#: ``format`` of a dataset's ``manifest.json`` (= ``slipkit.data.dataset.FORMAT``).
DATASET_FORMAT = "slipkit-dataset"
#: ``format`` of a run's ``run.json`` (= ``slipkit.train.runs.RUN_FORMAT``).
RUN_FORMAT = "slipkit-run"
#: ``format`` of a bundle's ``manifest.json`` (= ``slipkit.runtime.bundle.FORMAT``).
BUNDLE_FORMAT = "slipkit-bundle"
# The three are repeated here (tests/robustness/test_write_safety.py checks they match)
# because their modules import pandas / omegaconf / onnxruntime, and the runtime must be
# able to import this module without them.

#: Kinds recognised by a manifest: a folder inside one of them is never written into.
MANIFEST_KINDS = ("dataset", "run", "bundle")
#: Every kind a command writes (``demo`` and ``sweep``: recognised by their :class:`Layout`).
KINDS = (
    *MANIFEST_KINDS,
    "evaluation",
    "comparison",
    "closedloop",
    "demo",
    "sweep",
    "lerobot",
)
#: ``format`` of ``meta/slipkit.json`` in a LeRobot dataset that ``slipkit
#: export-dataset`` wrote (= ``slipkit.data.lerobot.MARKER_FORMAT``).
LEROBOT_FORMAT = "slipkit-lerobot"
#: Largest file read to recognise it (a summary or ``best.json`` is a few kB).
MAX_RECOGNISED_BYTES = 16 << 20


@dataclass(frozen=True)
class Layout:
    """What a command writes into its output folder, by name (``slipkit demo``, ``sweep``).

    Defined by the command beside the code that writes those names, and handed to
    :func:`check_out_path` (``layout=``): a folder is that command's earlier output,
    which it may write into again, when it holds some of ``entries`` and nothing else
    (hidden names aside: slipkit's own temporary ones), and each entry present passes
    its test in ``marks``.

    Attributes
    ----------
    kind : str
        One of :data:`KINDS`, for the messages (``is not a slipkit demo``).
    entries : frozenset of str
        Every name the command writes directly under its output folder.
    marks : mapping of str to callable
        Entry name -> ``test(path) -> bool`` (a report's title, a folder, a JSON marker).
    """

    kind: str
    entries: frozenset[str]
    marks: Mapping[str, Callable[[Path], bool]] = field(default_factory=dict)

    def holds(self, path: Path | str) -> bool:
        """Whether ``path`` is a folder this layout recognises (see the class docstring)."""
        path = Path(path)
        if path.is_symlink() or not path.is_dir():
            return False
        names = {p.name for p in path.iterdir() if not p.name.startswith(".")}
        if not names or not names <= self.entries:
            return False
        return all(test(path / n) for n, test in self.marks.items() if n in names)


def sha256_bytes(data: bytes) -> str:
    """Hex sha256 of a byte string."""
    return hashlib.sha256(data).hexdigest()


def sha256_file(path: Path, chunk: int = 1 << 20) -> str:
    """Hex sha256 of a file, read in 1 MiB chunks."""
    digest = hashlib.sha256()
    with open(path, "rb") as fh:
        while block := fh.read(chunk):
            digest.update(block)
    return digest.hexdigest()


# -- what a folder is ---------------------------------------------------------------------
def _json_field(path: Path, key: str) -> object:
    """``obj[key]`` of the JSON object in ``path``; None when unreadable or absent."""
    try:
        obj = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, ValueError):
        return None
    return obj.get(key) if isinstance(obj, dict) else None


def read_json_object(path: Path | str) -> dict[str, object] | None:
    """The JSON object in the regular file ``path``; None when it is anything else.

    None for a missing, unreadable, non-regular (FIFO, device) or larger than
    :data:`MAX_RECOGNISED_BYTES` file, and for JSON that is not an object: what
    recognisers of slipkit's own files call (a FIFO is never opened, so never waited on).
    """
    try:
        st = os.stat(path)
        if not stat.S_ISREG(st.st_mode) or st.st_size > MAX_RECOGNISED_BYTES:
            return None
        obj = json.loads(Path(path).read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, ValueError):
        return None
    return obj if isinstance(obj, dict) else None


def first_line(path: Path | str) -> str:
    """The first line of the regular text file ``path``; ``""`` for anything else."""
    try:
        if not stat.S_ISREG(os.stat(path).st_mode):
            return ""
        with open(path, encoding="utf-8") as fh:
            return fh.readline()
    except (OSError, UnicodeDecodeError):
        return ""


def manifest_kind(path: Path | str) -> str | None:
    """``"dataset"``, ``"run"`` or ``"bundle"`` when ``path`` is such a folder, else None.

    Recognised by the manifest alone (``manifest.json`` or ``run.json`` and its
    ``format``), not by the files' checksums: this says what a folder *is*, not
    whether it is intact.
    """
    path = Path(path)
    if not path.is_dir():
        return None
    fmt = _json_field(path / "manifest.json", "format")
    if fmt == DATASET_FORMAT:
        return "dataset"
    if fmt == BUNDLE_FORMAT:
        return "bundle"
    if _json_field(path / "run.json", "format") == RUN_FORMAT:
        return "run"
    return None


def folder_kind(path: Path | str) -> str | None:
    """The kind of slipkit output ``path`` is (one of :data:`KINDS`), or None.

    ``evaluation``: ``<run>/evaluations/<name>`` holding a ``metrics.json`` with
    ``run`` and ``dataset`` (what ``slipkit evaluate`` writes); ``comparison``: a
    ``report.md`` titled ``# Comparison:`` beside ``metrics.csv`` (``slipkit
    compare``); ``closedloop``: a ``report.md`` titled ``# Closed loop:`` beside
    ``summary.csv`` and ``results.csv`` (``slipkit closedloop``); ``lerobot``: a LeRobot
    dataset whose ``meta/slipkit.json`` says slipkit wrote it (``slipkit export-dataset``;
    a LeRobot dataset from any other tool is not one). A demo's or a sweep's folder is
    recognised by the command's own :class:`Layout` (``slipkit.demo.LAYOUT``,
    ``slipkit.train.optuna_sweep.LAYOUT``).
    """
    path = Path(path)
    kind = manifest_kind(path)
    if kind is not None or not path.is_dir():
        return kind
    if _json_field(path / "meta" / "slipkit.json", "format") == LEROBOT_FORMAT:
        return "lerobot"
    metrics = path / "metrics.json"
    if (
        path.parent.name == "evaluations"
        and manifest_kind(path.parent.parent) == "run"
        and _json_field(metrics, "run") is not None
        and isinstance(_json_field(metrics, "dataset"), dict)
    ):
        return "evaluation"
    if (path / "metrics.csv").is_file() and first_line(path / "report.md").startswith(
        "# Comparison:"
    ):
        return "comparison"
    if (
        (path / "summary.csv").is_file()
        and (path / "results.csv").is_file()
        and first_line(path / "report.md").startswith("# Closed loop:")
    ):
        return "closedloop"
    return None


# -- where a command may write ------------------------------------------------------------
def _where(option: str | None, path: Path) -> str:
    return f"{option}={path}" if option else str(path)


def _resolved(path: Path | str) -> Path:
    """Absolute path with every symlink of its existing part followed."""
    return Path(os.path.abspath(path)).resolve()


def check_plain_name(name: str, *, option: str = "name") -> str:
    """``name`` if it is a plain folder name, else a :class:`SlipkitError` naming ``option``.

    A plain name has no ``/`` or ``\\``, is not empty, ``.`` or ``..`` and does not
    start with a dot (hidden names are slipkit's own temporary folders).
    """
    problem = (
        "is empty"
        if not name.strip()
        else "holds a path separator"
        if "/" in name or "\\" in name or os.sep in name
        else "is a hidden or relative name (starts with '.')"
        if name.startswith(".")
        else "holds a NUL byte"
        if "\0" in name
        else None
    )
    if problem:
        raise SlipkitError(
            f"{option}={name!r}: {problem}; expected a plain folder name such as 'test-set'"
        )
    return name


def child_folder(parent: Path | str, name: str, *, option: str = "name") -> Path:
    """``parent / name`` for a plain ``name`` that resolves directly under ``parent``.

    Refuses (:class:`SlipkitError` naming ``option``) what :func:`check_plain_name`
    refuses, and a result that a symlink (``parent`` itself or ``name``) sends
    anywhere else.
    """
    check_plain_name(name, option=option)
    parent = Path(parent)
    target = parent / name
    expected = _resolved(parent.parent) / parent.name / name
    actual = _resolved(target)
    if actual != expected:
        raise SlipkitError(
            f"{option}={name!r}: {target} resolves to {actual}, outside {parent}; "
            "refusing to write there"
        )
    return target


def _check_target(
    target: Path,
    *,
    overwrite: bool,
    kind: str | None,
    option: str | None,
    inside: Path | str | None,
    layout: Layout | None = None,
) -> None:
    """The rules on the folder itself: same-kind overwrite, never inside a slipkit folder."""
    where = _where(option, target)
    if layout is not None:
        kind = layout.kind
    if target.is_symlink():
        raise SlipkitError(
            f"{where}: is a symbolic link; refusing to replace it (name the folder itself)"
        )
    if target.exists():
        if not overwrite:
            raise SlipkitError(
                f"{where}: already exists (pass overwrite=true to replace it)"
            )
        what = f"a slipkit {kind}" if kind else "a slipkit folder this command writes"
        if not target.is_dir():
            raise SlipkitError(
                f"{where}: exists and is not {what} (a file); refusing to replace it"
            )
        empty = not any(target.iterdir())
        same = (
            layout.holds(target)
            if layout is not None
            else kind is not None and folder_kind(target) == kind
        )
        if not empty and not same:
            raise SlipkitError(
                f"{where}: exists and is not {what}; refusing to replace it"
            )
    allowed = None if inside is None else _resolved(inside)
    for parent in _resolved(target).parents:
        if parent == allowed:
            continue
        pkind = manifest_kind(parent)
        if pkind is not None:
            raise SlipkitError(
                f"{where}: is inside the slipkit {pkind} {parent}; refusing to write "
                "into it (choose a folder outside it)"
            )


def check_out_path(
    out: Path | str,
    *,
    inputs: Mapping[str, Path | str | None] | None = None,
    option: str = "out",
    kind: str | None = None,
    overwrite: bool = False,
    inside: Path | str | None = None,
    layout: Layout | None = None,
) -> Path:
    """Refuse an output folder that could destroy data; return ``out`` as a Path.

    Call it before any work, naming the command's option. The rules:

    * ``out`` must not be, contain or sit inside any of ``inputs`` (compared after
      following symlinks);
    * ``out`` must not sit inside a dataset, run or bundle folder (any ancestor with a
      slipkit manifest), except the folder ``inside`` (``slipkit evaluate`` writes into
      its run's ``evaluations/``);
    * an existing ``out`` is replaced only with ``overwrite`` and only when it is a
      folder of the same ``kind`` (:func:`folder_kind`) or empty; never a file, a
      symlink or a folder of anything else.

    Parameters
    ----------
    out : path-like
        The folder the command will create or replace.
    inputs : mapping of str to path-like, optional
        The command's inputs, by option name (``{"path": ...}``); None entries are skipped.
    option : str
        The option that named ``out``, for the message (``out``, ``run_dir``).
    kind : str, optional
        One of :data:`KINDS`: what the command writes.
    overwrite : bool
        Whether the user asked to replace an existing ``out``.
    inside : path-like, optional
        A slipkit folder ``out`` may sit inside.
    layout : Layout, optional
        What the command writes into ``out`` (its ``kind`` replaces ``kind``): an
        existing ``out`` it :meth:`~Layout.holds` is accepted (with ``overwrite``).

    Raises
    ------
    SlipkitError
        Naming ``option``, ``out`` and the rule it breaks.
    """
    out = Path(out)
    _check_inputs(out, inputs, option, what="write there")
    _check_target(
        out,
        overwrite=overwrite,
        kind=kind,
        option=option,
        inside=inside,
        layout=layout,
    )
    return out


def _check_inputs(
    out: Path,
    inputs: Mapping[str, Path | str | None] | None,
    option: str,
    *,
    what: str,
) -> None:
    """``out`` is not, is not inside and does not contain any of ``inputs``."""
    where = _where(option, out)
    res = _resolved(out)
    for name, given in (inputs or {}).items():
        if given is None or not str(given):
            continue
        inp = _resolved(given)
        relation = (
            "is"
            if inp == res or _same_file(out, given)
            else "is inside"
            if inp in res.parents
            else "contains"
            if res in inp.parents
            else None
        )
        if relation:
            raise SlipkitError(
                f"{where}: {relation} the input {name}={given}; refusing to {what} "
                "(an output never replaces or enters its own input)"
            )


def _same_file(a: Path | str, b: Path | str) -> bool:
    """Whether ``a`` and ``b`` exist and are one file (same inode: a hard link too)."""
    try:
        return os.path.samefile(a, b)
    except (OSError, ValueError):
        return False


#: ``stat`` file types that are never written to, by what a message calls them
_SPECIAL = (
    (stat.S_ISFIFO, "a FIFO (named pipe)"),
    (stat.S_ISSOCK, "a socket"),
    (stat.S_ISCHR, "a character device"),
    (stat.S_ISBLK, "a block device"),
)


def check_out_file(
    path: Path | str,
    *,
    option: str,
    inputs: Mapping[str, Path | str | None] | None = None,
    is_own: Callable[[Path], bool] | None = None,
    what: str = "a file slipkit writes there",
) -> Path:
    """Refuse a single output file that could destroy data; return it as a Path.

    For options naming one file (``slipkit-run --json``, a sweep's ``best.json`` or
    SQLite study). Call it before any work; :func:`write_out_file` checks again at
    the write. The rules:

    * ``path`` is not one of ``inputs`` (the same file, a hard link included) and not
      inside one of them;
    * ``path`` is not a symbolic link, a folder, a FIFO, a socket or a device;
    * ``path`` does not sit inside a dataset, run or bundle (it would break their
      checksums);
    * an existing regular file is replaced only when ``is_own(path)`` says it is what
      the command writes there (a summary written again); without ``is_own`` never.

    Parameters
    ----------
    path : path-like
        The file the command will write.
    option : str
        The option that named it, for the message (``--json``).
    inputs : mapping of str to path-like, optional
        The command's inputs, by option name; None entries are skipped.
    is_own : callable, optional
        ``is_own(path) -> bool``: an existing file the command may replace.
    what : str
        What ``is_own`` recognises, for the message (``a slipkit-run summary``).

    Raises
    ------
    SlipkitError
        ``<option>=<path>: <the rule it breaks>``.
    """
    path = Path(path)
    where = _where(option, path)
    try:
        st = os.lstat(path)
    except FileNotFoundError:
        st = None
    except (OSError, ValueError) as exc:  # a NUL byte, a parent that is a file
        why = exc.strerror if isinstance(exc, OSError) and exc.strerror else exc
        raise SlipkitError(f"{where}: cannot be written: {why}") from None
    if st is not None:
        if stat.S_ISLNK(st.st_mode):
            raise SlipkitError(
                f"{where}: is a symbolic link; refusing to replace it "
                "(name the file itself)"
            )
        if stat.S_ISDIR(st.st_mode):
            raise SlipkitError(f"{where}: is a folder; refusing to replace it")
        for test, name in _SPECIAL:
            if test(st.st_mode):
                raise SlipkitError(
                    f"{where}: is {name}, not a regular file; refusing to write to it"
                )
    for parent in _resolved(path).parents:
        pkind = manifest_kind(parent)
        if pkind is not None:
            raise SlipkitError(
                f"{where}: is inside the slipkit {pkind} {parent}; refusing to write "
                "into it (choose a file outside it)"
            )
    _check_inputs(path, inputs, option, what="write there")
    if st is not None and not (is_own is not None and is_own(path)):
        raise SlipkitError(f"{where}: exists and is not {what}; refusing to replace it")
    return path


def write_out_file(
    path: Path | str,
    text: str,
    *,
    option: str,
    inputs: Mapping[str, Path | str | None] | None = None,
    is_own: Callable[[Path], bool] | None = None,
    what: str = "a file slipkit writes there",
) -> Path:
    """Check ``path`` again (:func:`check_out_file`), then write ``text`` atomically.

    Checked again because the command ran in between (a replay, a study) and the name
    may have changed meanwhile. Written through a temporary file in the same folder
    and a rename (:func:`atomic_write_text`); parent folders it creates are removed
    again when the write fails. An operating-system error (a read-only folder, a full
    disk) is a :class:`SlipkitError` naming ``option`` and the path.
    """
    path = check_out_file(path, option=option, inputs=inputs, is_own=is_own, what=what)
    created = [p for p in (path.parent, *path.parent.parents) if not p.exists()]
    try:
        atomic_write_text(path, text)
    except (OSError, ValueError) as exc:
        for parent in created:  # deepest first; one that holds anything stays
            with contextlib.suppress(OSError):
                parent.rmdir()
        why = exc.strerror if isinstance(exc, OSError) and exc.strerror else exc
        raise SlipkitError(f"{_where(option, path)}: cannot write it: {why}") from None
    return path


def check_writable(folder: Path | str, *, option: str) -> None:
    """Refuse a folder the command cannot create files in, naming ``option``.

    Tried with an anonymous temporary file (``O_TMPFILE`` where the system has it:
    no name ever appears), not :func:`os.access`, which ignores read-only mounts and
    says yes to root.
    """
    try:
        with tempfile.TemporaryFile(dir=folder):
            pass
    except OSError as exc:
        why = exc.strerror or exc
        raise SlipkitError(f"{option}={folder}: cannot write there: {why}") from None


# -- leftovers of interrupted writes ------------------------------------------------------
def recover_leftovers(target: Path | str) -> list[Path]:
    """Restore or report what an interrupted :func:`atomic_dir` left beside ``target``.

    An ``.<name>.old-*`` folder holding the previous copy while ``target`` is missing
    (a kill between the two renames of an overwrite) is renamed back to ``target``
    and logged. Any other ``.<name>.old-*`` or ``.<name>.tmp-*`` folder is reported
    with a warning naming it (it is never taken as complete, and never deleted here:
    it may hold the only copy of something). Returns the leftovers still present.
    """
    target = Path(target)
    parent = target.parent
    if not parent.is_dir():
        return []
    name = glob.escape(target.name)
    left: list[Path] = []
    for old in sorted(parent.glob(f".{name}.old-*")):
        aside = old / target.name
        if not (target.exists() or target.is_symlink()) and (
            aside.exists() or aside.is_symlink()
        ):
            os.replace(aside, target)
            with contextlib.suppress(OSError):
                old.rmdir()
            log.warning(
                "%s: restored from %s, where an interrupted overwrite had left it",
                target,
                old,
            )
            continue
        if old.is_dir() and not any(old.iterdir()):
            # Killed after creating the aside folder, before moving anything into it.
            with contextlib.suppress(OSError):
                old.rmdir()
            continue
        log.warning(
            "%s: left by an interrupted overwrite of %s (it holds the previous copy); "
            "check %s, then delete the leftover",
            old,
            target,
            target,
        )
        left.append(old)
    for tmp in sorted(parent.glob(f".{name}.tmp-*")):
        log.warning(
            "%s: an incomplete write of %s left by an interrupted slipkit process "
            "(never read as complete); delete it unless a slipkit command is writing "
            "%s right now",
            tmp,
            target,
            target,
        )
        left.append(tmp)
    return left


# -- permissions --------------------------------------------------------------------------
def _umask() -> int:
    """The process umask. ``os.umask`` can only set it, so set it back at once."""
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def _give_umask(root: Path) -> None:
    """Folders ``0o777 & ~umask``, files ``0o666 & ~umask`` under ``root`` (inclusive).

    ``tempfile`` creates folders 0700 and files 0600 (private on purpose, for
    temporary files); a finished dataset, run or bundle must get the user's usual
    permissions so that a copy (``rsync -a``) is readable where the user expects.
    """
    mask = _umask()
    dmode, fmode = 0o777 & ~mask, 0o666 & ~mask
    os.chmod(root, dmode)
    for here, dirs, files in os.walk(root):
        for d in dirs:
            p = os.path.join(here, d)
            if not os.path.islink(p):
                os.chmod(p, dmode)
        for f in files:
            p = os.path.join(here, f)
            if not os.path.islink(p):
                exe = os.stat(p).st_mode & stat.S_IXUSR
                os.chmod(p, (dmode if exe else fmode))


# -- writes -------------------------------------------------------------------------------
#: the temporary folder of every :func:`atomic_dir` block still running -> its target
#: (absolute paths), so that what is written inside can name its final location
_PENDING: dict[str, str] = {}


def final_path(path: Path | str) -> Path:
    """``path`` as it will be named once the :func:`atomic_dir` blocks around it finish.

    A run trained inside another command's output (``slipkit compare`` writes its runs
    into its own temporary folder) would otherwise record the temporary name, which is
    gone after the rename. Outside any such block ``path`` is returned unchanged.
    """
    here = os.path.abspath(path)
    moved = False
    for _ in range(len(_PENDING)):  # nested blocks: a target may lie in an outer temp
        inside = [
            (tmp, target)
            for tmp, target in list(_PENDING.items())
            if here == tmp or here.startswith(tmp + os.sep)
        ]
        if not inside:
            break
        tmp, target = inside[0]
        here, moved = target + here[len(tmp) :], True
    return Path(here) if moved else Path(path)


def _swap(tmp: Path, target: Path) -> None:
    """Replace ``target`` by ``tmp`` with two renames; on any failure put the old one back."""
    old = Path(tempfile.mkdtemp(prefix=f".{target.name}.old-", dir=target.parent))
    aside = old / target.name
    try:
        os.replace(target, aside)
        os.replace(tmp, target)
    except BaseException:
        # Decide from the disk, not from flags: an interrupt can land between a rename
        # and the next statement.
        if not tmp.exists() and target.exists():
            # Both renames completed: the write is done; drop the old copy, re-raise.
            shutil.rmtree(old, ignore_errors=True)
            raise
        if aside.exists() and not (target.exists() or target.is_symlink()):
            os.replace(aside, target)  # the old folder is back under its name
        with contextlib.suppress(OSError):
            old.rmdir()  # only when empty: never deletes the old copy
        raise
    shutil.rmtree(old, ignore_errors=True)


@contextlib.contextmanager
def atomic_dir(
    target: Path | str,
    *,
    overwrite: bool = False,
    kind: str | None = None,
    inside: Path | str | None = None,
) -> Iterator[Path]:
    """Yield a temporary sibling folder that becomes ``target`` only on success.

    The folder is created beside ``target`` (same filesystem, so the final rename
    is atomic). If the body raises, or the process dies, ``target`` is untouched:
    a reader never sees a half-written folder under the final name. Leftover
    ``.<name>.tmp-*`` folders from a killed process are never taken as complete,
    and are reported (:func:`recover_leftovers`) on the next write or read.

    Parameters
    ----------
    target : path-like
        The folder to create.
    overwrite : bool
        Replace an existing ``target``; only a folder of the same ``kind``
        (:func:`folder_kind`) or an empty folder is ever replaced.
    kind : str, optional
        What is written (one of :data:`KINDS`); without it nothing is replaced.
    inside : path-like, optional
        The one slipkit folder ``target`` may sit inside (an evaluation's run).

    Raises
    ------
    SlipkitError
        ``target`` exists and may not be replaced, or sits inside a slipkit folder.
    """
    target = Path(target)
    recover_leftovers(target)
    _check_target(target, overwrite=overwrite, kind=kind, option=None, inside=inside)
    # the parents this write creates (runs/<name>/ for a first run): a failed write
    # removes them again if they are still empty, so a refusal leaves nothing behind
    created = [p for p in (target.parent, *target.parent.parents) if not p.exists()]
    target.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{target.name}.tmp-", dir=target.parent))
    _PENDING[os.path.abspath(tmp)] = os.path.abspath(target)
    try:
        yield tmp
        _give_umask(tmp)
        if target.exists() or target.is_symlink():
            # Checked again: the body ran for a while and the folder may have changed.
            _check_target(
                target, overwrite=overwrite, kind=kind, option=None, inside=inside
            )
            _swap(tmp, target)
        else:
            os.replace(tmp, target)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        for parent in created:  # deepest first; one that holds anything stays
            with contextlib.suppress(OSError):
                parent.rmdir()
        raise
    finally:
        _PENDING.pop(os.path.abspath(tmp), None)


def atomic_write_text(path: Path | str, text: str) -> None:
    """Write ``text`` to ``path`` through a temporary file and a rename.

    The file gets the user's umask (``0o666 & ~umask``), not ``mkstemp``'s 0600.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.tmp-", dir=path.parent)
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as fh:
            fh.write(text)
        os.chmod(tmp, 0o666 & ~_umask())
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        raise
