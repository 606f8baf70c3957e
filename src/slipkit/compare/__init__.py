"""``slipkit compare``: every estimator of a sensor family on one split, its accuracy and its cost.

Modules: :mod:`~slipkit.compare.adapters` (a task's metrics -> one unified row),
:mod:`~slipkit.compare.costs` (fit time; export + runtime-loop latency),
:mod:`~slipkit.compare.table` (the table, the Pareto front),
:mod:`~slipkit.compare.plots` (the PNGs), :mod:`~slipkit.compare.report` (report.md),
:mod:`~slipkit.compare.commands` (:func:`compare_main`).
"""
