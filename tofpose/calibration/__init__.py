"""Calibrations: the bench (camera mount, target placement), the range error, the
covariance scale."""
