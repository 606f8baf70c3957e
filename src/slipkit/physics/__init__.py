"""Closed-form sensor physics and geometry shared by the simulator, the analytic
baselines and the models (numpy only, no pandas, so any part of slipkit can use it)."""
