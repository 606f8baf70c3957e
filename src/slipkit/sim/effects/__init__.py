"""Effect modules: importing this package registers every effect in ``EFFECTS``.

One module per physical domain (``common`` for sensor-agnostic effects such as
white noise and ADC quantisation, one per sensor family for the rest). Modules are
found with ``pkgutil`` so adding an effect module needs no edit here.
"""

from __future__ import annotations

import importlib
import pkgutil

import slipkit.families as _families

for _mod in pkgutil.iter_modules(__path__):
    importlib.import_module(f"{__name__}.{_mod.name}")
# and family folders' effects (slipkit.families.PLUGIN_MODULES["effects"])
_families.load_plugins("effects")
