"""Plain NumPy/OpenCV statements of ``tofpose.core.kernels``."""
