"""The pixel fit's compiled kernels: ``images`` (the discs' images over the window
pixels), ``derivatives`` (with their pose derivatives) and ``normal`` (an iteration's
normal equations from them); ``reference/`` and ``fit.py`` keep the same arithmetic in
NumPy as the reference."""
