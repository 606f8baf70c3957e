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
(:mod:`.adapter`) and the closed-loop scenario (:mod:`.scenario`). Its record, :data:`FAMILY`, lists them; they register when the stages load the
record's plug-in modules (``slipkit.families.load_plugins``). The recordings' importers stay in
``slipkit.data.importers``.
"""

from slipkit.families import DETECTION_TASK, WINDOW_TASK, Family

_F = "slipkit.families.biotac."

FAMILY = Family(
    name="biotac",
    sensor="biotac",
    tasks=(
        _F + "force_task:ForceRegression",
        _F + "direction_task:FingerDirection",
        WINDOW_TASK,
        _F + "grasp_task:GraspStability",
        DETECTION_TASK,
    ),
    deploys=(_F + "force_task:ForceRegression", WINDOW_TASK, DETECTION_TASK),
    compares=(_F + "force_task:ForceRegression", WINDOW_TASK, DETECTION_TASK),
    exporters=(
        *(_F + "export." + m for m in ("detectors", "force", "window_rules")),
        "slipkit.export.window_stats",
        "slipkit.export.generic",
        "slipkit.export.frame_gru",
    ),
    scenes=("biotac_force_probe", "biotac_lift_slip", "biotac_lift_slip_hard"),
    comparisons=("biotac_force", "biotac_slip", "biotac_slip_type", "dos_real"),
    scenario="biotac",
    docs=("families/biotac.md",),
    detectors=tuple(_F + m for m in ("detectors", "slip_twist", "electrode_energy")),
    plugins={
        "deployers": (_F + "deploy",),
        "adapters": (_F + "adapter",),
        "scenarios": (_F + "scenario",),
        "effects": (_F + "effects",),
    },
)
