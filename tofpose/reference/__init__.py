"""The pipeline's arithmetic stated in plain NumPy and SciPy, one function per equation
of the paper (and per rule of ours), written to be read against the paper rather than to
be fast: the oracle the compiled kernels (``tofpose.kernels``) are tested against.

An import-linter contract (``pyproject.toml``) forbids this package from importing the
kernels or the pipeline, so a test that compares the two compares two implementations,
not one implementation with itself. docs/algorithm.md, "Equations and where they are
computed", maps each equation to its function here and to its compiled counterpart.
Modules: ``camera`` (Eqs. 7-9), ``extraction`` (§3.1-§3.2: levels, the active set,
components, Eqs. 11-18, the gates and the penalty), ``persistence`` (§3.4's combination),
``centroids`` (Eqs. 19-20), ``sigmas`` (the measurement sigmas, Eq. 21), ``matching``
(§4: Eqs. 25-39, the one-to-one step, the rigid residual check), ``pose`` (§5: Eqs. 40-52
and the ML refinement, its covariance and the leave-one-out spread), ``two_centres`` (the
split of a merged pair).
"""
