"""Estimators: measurements made from sensor data (estimator.fiducial: a pose from a camera image)."""
