"""BioTac's exporters: the force-derivative and pressure-vibration graphs (:mod:`.detectors`)
and their parity benchmark (:mod:`.parity`), the force regressors' graphs (:mod:`.force`) and
the analytic window rules' graphs (:mod:`.window_rules`)."""

# The export stage first: its import registers every exporter in one order (these modules
# included), so a module here imported on its own never meets a half-imported sibling.
import slipkit.export  # noqa: F401
