"""Tasks: one module per model family (see :mod:`slipkit.train.task`)."""
