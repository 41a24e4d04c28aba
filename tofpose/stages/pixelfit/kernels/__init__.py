"""The pixel fit's compiled kernels (``images``: the discs' images over the window
pixels); ``model.py`` keeps the same arithmetic in NumPy as the reference."""
