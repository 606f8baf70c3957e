"""Errors slipkit raises for bad input: each names the file, field or frame at fault."""

from __future__ import annotations


class SlipkitError(Exception):
    """Base class of every error slipkit raises on purpose (the CLI prints these
    without a traceback and exits with status 2)."""


class DatasetError(SlipkitError, ValueError):
    """A dataset folder or an in-memory dataset breaks the format.

    Parameters
    ----------
    where : str
        The file (``streams/force.parquet``) or object (``stream 'force'``) at fault.
    problem : str
        What is wrong, naming the field or column and what was expected.
    """

    def __init__(self, where: str, problem: str) -> None:
        self.where = where
        self.problem = problem
        super().__init__(f"{where}: {problem}")


class TrainingDataError(SlipkitError, ValueError):
    """The training side cannot fit the estimator (too few trials or distinct values).

    A ``ValueError`` too, as scikit-learn estimators raise for unusable data.
    """


class SourceFormatError(SlipkitError, ValueError):
    """A source file handed to an importer does not have the layout it expects."""


class SlipkitWarning(UserWarning):
    """Base class of slipkit's own warnings (a convention the input breaks, a number that
    cannot be trusted); the ``slipkit`` command shows each distinct one once per run."""
