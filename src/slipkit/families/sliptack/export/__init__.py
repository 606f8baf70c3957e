"""SlipTack's exporters: the speed graph (:mod:`.speed`), its slip decision
(:mod:`.detector`), the onset, spectral and torsional graphs, and the parity benchmark
(:mod:`.parity`)."""

# The export stage first: its import registers every exporter in one order (these modules
# included), so a module here imported on its own never meets a half-imported sibling.
import slipkit.export  # noqa: F401
