"""Errors the gripper-PC runtime raises: each names the file and field, or the frame, at fault.

Both derive from :class:`slipkit.errors.SlipkitError`, which imports only the standard
library (checked by ``tests/runtime/test_cli.py``), so the runtime stays numpy +
onnxruntime only while the ``slipkit`` CLI and ``slipkit-run`` treat these errors alike.
"""

from __future__ import annotations

from slipkit.errors import SlipkitError


def printable(text: str) -> str:
    """``text`` with every non-printable character escaped (``\\n``, ``\\x00``).

    A field name, file name or value from a hostile file may hold a newline; an
    error message must stay one line.
    """
    if text.isprintable():
        return text
    return "".join(c if c.isprintable() else repr(c)[1:-1] for c in text)


class BundleError(SlipkitError, ValueError):
    """A bundle folder is incomplete, tampered with, or its manifest breaks the schema.

    Parameters
    ----------
    file : str
        The file at fault (``exports/tactip_svm/manifest.json``).
    field : str or None
        The manifest field at fault in dotted form (``frame.rate_hz``,
        ``preprocessing[1].scale``); None when the whole file is at fault.
    problem : str
        What is wrong and what was expected.
    """

    def __init__(self, file: str, field: str | None, problem: str) -> None:
        self.file = file
        self.field = field
        self.problem = problem
        where = file if field is None else f"{file}: field '{field}'"
        super().__init__(printable(f"{where}: {problem}"))


class FrameError(SlipkitError, ValueError):
    """A recorded or received frame does not match the bundle's frame spec.

    Parameters
    ----------
    where : str
        The file (``replay.npz``) or socket (``udp 127.0.0.1:9000``) at fault.
    problem : str
        What is wrong, naming the array or header field and what was expected.
    """

    def __init__(self, where: str, problem: str) -> None:
        self.where = where
        self.problem = problem
        super().__init__(printable(f"{where}: {problem}"))


class OptionError(SlipkitError, ValueError):
    """A command-line option or a keyword argument of the runtime is out of range.

    Parameters
    ----------
    option : str
        The option (``--timeout``) or argument (``timeout_s``) at fault.
    problem : str
        What is wrong and what was expected.
    """

    def __init__(self, option: str, problem: str) -> None:
        self.option = option
        self.problem = problem
        super().__init__(printable(f"{option}: {problem}"))
