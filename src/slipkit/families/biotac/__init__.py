"""The BioTac family: a fluid-filled fingertip with 19 electrodes, a pressure sensor and a
thermistor (Su et al. 2015).

One folder, by role (``docs/extending.md``): :mod:`.physics` (electrode layout and the
backbone's linear response), :mod:`.scene` and :mod:`.effects` (simulated force probes and
grasp-and-lifts), the slip detectors :mod:`.detectors` (pressure vibration, force
derivative), the analytic window rules :mod:`.slip_twist` (linear vs rotational slip) and
:mod:`.electrode_energy` (motion vs touch on BioTacSP-DoS), the force regressors :mod:`.force`, the tasks :mod:`.force_task` (force
regression), :mod:`.direction_task` (finger force direction) and :mod:`.grasp_task`
(grasp stability from BioTac SP readings), the exporters
(:mod:`.export`), the force task's deployer (:mod:`.deploy`) and comparison adapter
(:mod:`.adapter`) and the closed-loop scenario (:mod:`.scenario`). They register through
``slipkit.families.PLUGIN_MODULES``. The recordings' importers stay in
``slipkit.data.importers``.
"""
