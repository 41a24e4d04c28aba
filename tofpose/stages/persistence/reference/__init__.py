"""Plain NumPy/SciPy/OpenCV statement of the persistence stage's kernels: their oracle
in tests and ``PosePipeline(implementation="reference")``'s arithmetic. Imports no
kernel and no numba."""
