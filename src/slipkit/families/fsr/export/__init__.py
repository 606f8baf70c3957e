"""FSR's exporters: the touch-and-slip graph (:mod:`.touch_slip`), the onset graphs
(:mod:`.onset`) and the parity benchmark (:mod:`.parity`)."""

# The export stage first: its import registers every exporter in one order (these modules
# included), so a module here imported on its own never meets a half-imported sibling.
import slipkit.export  # noqa: F401
