"""Every estimator slipkit defines, found by walking its packages.

As :func:`sklearn.utils.discovery.all_estimators` does for scikit-learn:
``tests/test_common.py`` runs scikit-learn's estimator checks over this list, so an
estimator added to any of these packages is checked without being named in a test.
The packages are imported by name (:mod:`importlib`), so this module adds no static
import edge between the stages.
"""

from __future__ import annotations

import importlib
import inspect
import pkgutil
from collections.abc import Iterable

from sklearn.base import BaseEstimator

#: the packages whose modules define estimators (learned models, analytic baselines, the
#: decision estimators exporters wrap) and the family folders
PACKAGES: tuple[str, ...] = (
    "slipkit.models",
    "slipkit.baselines",
    "slipkit.export",
    "slipkit.families",
)


def _modules(package: str) -> Iterable[str]:
    pkg = importlib.import_module(package)
    yield package
    for info in pkgutil.walk_packages(pkg.__path__, prefix=f"{package}."):
        yield info.name


def _declares_abstract(cls: type) -> bool:
    """A contract class (abstract methods left to subclasses) is not an estimator to run."""
    return any(
        getattr(getattr(cls, name, None), "__isabstractmethod__", False)
        for name in dir(cls)
        if not name.startswith("__")
    )


def all_estimators(
    packages: Iterable[str] = PACKAGES,
) -> list[tuple[str, type[BaseEstimator]]]:
    """``(name, class)`` of every concrete scikit-learn estimator defined in ``packages``.

    Classes are taken where they are defined (a re-export is not counted twice),
    abstract classes and private names (``_Name``) are left out, and the list is sorted
    by name so a parametrised test has stable ids.
    """
    found: dict[str, type[BaseEstimator]] = {}
    for package in packages:
        for module_name in _modules(package):
            module = importlib.import_module(module_name)
            for name, cls in inspect.getmembers(module, inspect.isclass):
                if (
                    cls.__module__ == module_name
                    and issubclass(cls, BaseEstimator)
                    and not name.startswith("_")
                    and not inspect.isabstract(cls)
                    and not _declares_abstract(cls)
                ):
                    found[f"{module_name}.{name}"] = cls
    return sorted(((cls.__name__, cls) for cls in found.values()), key=lambda t: t[0])
