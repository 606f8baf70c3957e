"""The SlipTack family: a whisker-like nib whose stick-slip frequency gives the slip speed.

One folder, by role (``docs/extending.md``): :mod:`.physics` (closed-form stick-slip),
:mod:`.scene` and :mod:`.effects` (simulated pulls and drops), the estimators
:mod:`.speed` (frequency -> speed), :mod:`.accel`, :mod:`.onset`, :mod:`.torsion` and
:mod:`.spectral`, the tasks (:mod:`.task`), the exporters (:mod:`.export`), the deployer
(:mod:`.deploy`), the comparison adapters (:mod:`.adapter`) and the closed-loop scenario
(:mod:`.scenario`). They register through ``slipkit.families.PLUGIN_MODULES``; the
runtime op of the prepared spectrum stays in ``slipkit.runtime.sliding_spectrum``.
"""
