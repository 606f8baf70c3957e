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
from collections.abc import Iterator, Mapping
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
#: Every kind a command writes.
KINDS = (*MANIFEST_KINDS, "evaluation", "comparison", "demo")
#: What a ``slipkit demo`` output folder holds (``configs/demo.yaml``).
DEMO_ENTRIES = frozenset({"data", "compare", "exports", "report.md"})


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


def _first_line(path: Path) -> str:
    try:
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
    compare``); ``demo``: a folder holding only ``data/``, ``compare/``, ``exports/``
    and ``report.md`` (``slipkit demo``; an interrupted demo may lack some of them).
    """
    path = Path(path)
    kind = manifest_kind(path)
    if kind is not None or not path.is_dir():
        return kind
    metrics = path / "metrics.json"
    if (
        path.parent.name == "evaluations"
        and manifest_kind(path.parent.parent) == "run"
        and _json_field(metrics, "run") is not None
        and isinstance(_json_field(metrics, "dataset"), dict)
    ):
        return "evaluation"
    if (path / "metrics.csv").is_file() and _first_line(path / "report.md").startswith(
        "# Comparison:"
    ):
        return "comparison"
    entries = {p.name for p in path.iterdir() if not p.name.startswith(".")}
    if entries and entries <= DEMO_ENTRIES:
        report = path / "report.md"
        if not report.exists() or _first_line(report).startswith("# slipkit demo"):
            return "demo"
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
) -> None:
    """The rules on the folder itself: same-kind overwrite, never inside a slipkit folder."""
    where = _where(option, target)
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
        if not empty and (kind is None or folder_kind(target) != kind):
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

    Raises
    ------
    SlipkitError
        Naming ``option``, ``out`` and the rule it breaks.
    """
    out = Path(out)
    where = _where(option, out)
    res = _resolved(out)
    for name, given in (inputs or {}).items():
        if given is None or not str(given):
            continue
        inp = _resolved(given)
        relation = (
            "is"
            if inp == res
            else "is inside"
            if inp in res.parents
            else "contains"
            if res in inp.parents
            else None
        )
        if relation:
            raise SlipkitError(
                f"{where}: {relation} the input {name}={given}; refusing to write "
                "there (an output never replaces or enters its own input)"
            )
    _check_target(out, overwrite=overwrite, kind=kind, option=option, inside=inside)
    return out


def check_out_file(path: Path | str, *, option: str) -> Path:
    """Refuse a single output file that could destroy data; return it as a Path.

    For options naming one file (``slipkit-run --json``): it may replace an existing
    file (a summary written again), but not a folder or a symlink, and it must not sit
    inside a dataset, run or bundle folder (it would break their checksums).
    """
    path = Path(path)
    where = _where(option, path)
    if path.is_symlink() or path.is_dir():
        raise SlipkitError(
            f"{where}: is a folder or a symbolic link; refusing to replace it"
        )
    for parent in _resolved(path).parents:
        pkind = manifest_kind(parent)
        if pkind is not None:
            raise SlipkitError(
                f"{where}: is inside the slipkit {pkind} {parent}; refusing to write "
                "into it (choose a file outside it)"
            )
    return path


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
