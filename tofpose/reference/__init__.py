"""The pipeline's arithmetic stated in plain NumPy and SciPy, one function per equation
of the paper (and per rule of ours), written to be read against the paper rather than to
be fast: the oracle the compiled kernels (``tofpose.kernels``) are tested against.

An import-linter contract (``pyproject.toml``) forbids this package from importing the
kernels or the pipeline, so a test that compares the two compares two implementations,
not one implementation with itself. docs/algorithm.md, "Equations and where they are
computed", maps each equation to its function here and to its compiled counterpart.
Modules: ``centroids`` (§3.4: Eqs. 19-20), ``pose`` (§5: Eqs. 40-52 and the ML
refinement, its covariance and the leave-one-out spread), ``two_centres`` (the split of a
merged pair).
"""
