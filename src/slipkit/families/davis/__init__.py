"""The DAVIS family: an event camera watching the contact patch (Rigi et al. 2018).

One folder, by role (``docs/extending.md``): :mod:`.physics` (the contact patch),
:mod:`.scene` and :mod:`.effects` (simulated releases: contact-change events, vibration
incidents, background events), the detectors :mod:`.polarity` (the paper's
event-polarity rule) and :mod:`.onset` (a straight one-sided loss of contact), the learned
:mod:`.classifier` (per-frame polarity counts and areas), the release task (:mod:`.task`),
the exporters (:mod:`.export`), the deployers (:mod:`.deploy`), the comparison adapter
(:mod:`.adapter`) and the closed-loop scenario (:mod:`.scenario`). They register through
``slipkit.families.PLUGIN_MODULES``; the runtime op ``davis_areas`` stays in
``slipkit.runtime.preprocessing``.
"""
