"""The BioTac family: a fluid-filled fingertip with 19 electrodes, a pressure sensor and a
thermistor (Su et al. 2015).

One folder, by role (``docs/extending.md``): :mod:`.physics` (electrode layout and the
backbone's linear response), :mod:`.scene` and :mod:`.effects` (simulated force probes and
grasp-and-lifts), the slip detectors :mod:`.detectors` (pressure vibration, force
derivative), the exporters (:mod:`.export`) and the closed-loop scenario
(:mod:`.scenario`). They register through ``slipkit.families.PLUGIN_MODULES``. The
recordings' importers stay in ``slipkit.data.importers``.
"""
