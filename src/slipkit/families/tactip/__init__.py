"""The TacTip family: a camera-tracked pin array whose pin velocities show slip.

One folder, by role: :mod:`.physics` (pin layout, Hertz contact), :mod:`.scene` and
:mod:`.effects` (the simulated gravity drop), :mod:`.features` (trials and datasets to
pin-velocity feature rows), the analytic pin-motion detector (:mod:`.detector`), the
frame tasks (:mod:`.task`, :mod:`.task_table`), the exporters (:mod:`.export`), the
deployer (:mod:`.deploy`), the comparison adapters (:mod:`.adapter`) and the closed-loop
scenario (:mod:`.scenario`). They register through ``slipkit.families.PLUGIN_MODULES``.
The pin-velocity features and their graph stay generic (``slipkit.features.pins``,
``slipkit.export.pins``: other pin and marker sensors use them), as does the SVM
(``slipkit.models.svm``).
"""
