"""The pixel fit's arithmetic in NumPy: the compiled kernels' statement and test oracle."""
