"""TacTip's exporters: the SVM's Gemm/Exp graph with the pin-velocity features inside
(:mod:`.svm`) and the pin-motion detector's graph with the pooled pin statistics
(:mod:`.detector`)."""

# The export stage first: its import registers every exporter in one order (these modules
# included), so a module here imported on its own never meets a half-imported sibling.
import slipkit.export  # noqa: F401
