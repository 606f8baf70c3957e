"""The GelSight family: marker tracking, pin-motion features, streaming detectors."""
