"""The pipeline's arithmetic stated in plain NumPy and SciPy, one function per equation
of the paper (and per rule of ours), written to be read against the paper rather than to
be fast: the oracle the compiled kernels (``tofpose.kernels``) are tested against.

An import-linter contract (``pyproject.toml``) forbids this package from importing the
kernels or the pipeline, so a test that compares the two compares two implementations,
not one implementation with itself. docs/algorithm.md, "Equations and where they are
computed", maps each equation to its function here and to its compiled counterpart.
Modules: ``camera`` (Eqs. 7-9), ``extraction`` (§3.1-§3.2: levels, the active set,
components, Eqs. 11-18, the gates and the penalty), ``ellipses`` and ``pair_fit`` (§3.3's
confirmation, and the model fit of a merged pair), ``two_centres`` (its split),
``persistence`` (§3.4's combination), ``centroids`` (Eqs. 19-20), ``mixed_pixels`` (surround
levels, occlusion, mixed pixels), ``sigmas`` (the measurement sigmas, Eq. 21), ``measure``
(the measurement stage whole), ``matching`` (§4: Eqs. 25-39, the one-to-one step, the
rigid residual check), ``triplets`` (the triplet hypotheses), ``pose`` (§5: Eqs. 40-52,
the ML refinement, its covariance, the outlier step, the range offset and the
leave-one-out spread), ``solve`` (the §5 stage whole), ``verify`` (the pose check),
``tracking`` (tracking mode's windows and search). Most functions carry the name,
arguments and returns of the kernel they restate, so the two can be swapped.
"""
