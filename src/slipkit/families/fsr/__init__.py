"""The FSR family: a force-sensing resistor under a fingertip (Gentile et al. 2020).

One folder, by role (``docs/extending.md``): :mod:`.physics` (the voltage divider and the
paper's calibration), :mod:`.scene` and :mod:`.effects` (simulated probe slides,
disturbances, wirings), the detectors :mod:`.touch_slip` (the paper's touch-and-slip rule)
and :mod:`.onset` (slip onset from the release's shape), the exporters (:mod:`.export`) and
the closed-loop scenario (:mod:`.scenario`). Training, deployment and comparison use the
generic stream-detection task, deployer and adapter. They register through
``slipkit.families.PLUGIN_MODULES``; the runtime op ``press_sign`` stays in
``slipkit.runtime.preprocessing``.
"""
