"""Analytic slip detectors from the papers, as scikit-learn estimators (see ``base``)."""
