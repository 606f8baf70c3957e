"""DAVIS's exporters: the polarity rule's area graph (:mod:`.polarity`), the onset rule's
graph (:mod:`.onset`) and the learned event-frame classifier's graph (:mod:`.classifier`)."""

# The export stage first: its import registers every exporter in one order (these modules
# included), so a module here imported on its own never meets a half-imported sibling.
import slipkit.export  # noqa: F401
