"""Runtime ops of one sensor family each: ``slipkit.runtime.ops.<family>``.

Every module here registers its ops (:func:`slipkit.runtime.preprocessing.register_op`)
when imported, and this package imports them all, so a family's op is a module of its
own and no shared module names it. Like the rest of the runtime they import numpy and
the standard library only (the gripper PC's rule): DAVIS's ``davis_areas``, FSR's
``press_sign``, GelSight's ``contact_window``, SlipTack's ``sliding_spectrum``.

A family shipped as its own package adds its ops the same way from outside: an entry
point of group :data:`ENTRY_POINT_GROUP` naming its op module, imported here after
slipkit's own. One that fails to import is reported as a warning naming it, and the
ops of the others still load (a bundle that needs the missing op is then refused,
naming the op and the ones known).
"""

from __future__ import annotations

import importlib
import importlib.metadata
import pkgutil
import warnings

#: the entry-point group through which an installed package adds runtime ops
ENTRY_POINT_GROUP = "slipkit.runtime_ops"

for _info in sorted(pkgutil.iter_modules(__path__), key=lambda i: i.name):
    importlib.import_module(f"{__name__}.{_info.name}")


def load_entry_points() -> list[str]:
    """Import every op module registered under :data:`ENTRY_POINT_GROUP`; the names
    of those imported. A module that fails to import is skipped with a warning."""
    loaded = []
    for ep in sorted(
        importlib.metadata.entry_points(group=ENTRY_POINT_GROUP), key=lambda e: e.name
    ):
        try:
            ep.load()
        except Exception as exc:  # third-party code: any error is reported, not fatal
            warnings.warn(
                f"runtime ops of entry point {ep.name!r} ({ep.value}) of group "
                f"{ENTRY_POINT_GROUP!r} not loaded: {type(exc).__name__}: {exc}",
                RuntimeWarning,
                stacklevel=2,
            )
        else:
            loaded.append(ep.name)
    return loaded


load_entry_points()
