"""Runtime ops of one sensor family each: ``slipkit.runtime.ops.<family>``.

Every module here registers its ops (:func:`slipkit.runtime.preprocessing.register_op`)
when imported, and this package imports them all, so a family's op is a module of its
own and no shared module names it. Like the rest of the runtime they import numpy and
the standard library only (the gripper PC's rule): DAVIS's ``davis_areas``, FSR's
``press_sign``, GelSight's ``contact_window``, SlipTack's ``sliding_spectrum``.
"""

from __future__ import annotations

import importlib
import pkgutil

for _info in sorted(pkgutil.iter_modules(__path__), key=lambda i: i.name):
    importlib.import_module(f"{__name__}.{_info.name}")
