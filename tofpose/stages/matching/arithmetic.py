"""The matching stage's arithmetic (§4) per implementation: ``COMPILED`` (its kernels and
SciPy's assignment) and ``REFERENCE`` (``reference``), each field with the kernel's
calling convention."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.optimize import linear_sum_assignment

from tofpose.stages.matching.kernels import annealing, residual_check, triplets
from tofpose.stages.matching.reference import matching as ref_matching
from tofpose.stages.matching.reference import triplets as ref_triplets


@dataclass(frozen=True)
class MatchingArithmetic:
    """§4: annealing, the one-to-one reading of its assignment, the rigid residual check
    and the triplet search."""

    name: str
    pair_potentials: Callable
    size_mismatch: Callable
    anneal_assignment: Callable
    #: pair potentials, size term and annealing in one call (``kernels.annealing``'s)
    soft_assignment: Callable
    one_to_one: Callable  # A (g, e + 1) -> (pairs (m, 2) int64, unmatched list)
    prune_pairs: Callable
    catalog_triplets: Callable
    triplet_search: Callable
    trials_needed: Callable


def _compiled_one_to_one(A: np.ndarray) -> tuple[np.ndarray, list[int]]:
    """``matching.one_to_one``: the cost matrix and the reading of the assignment
    compiled (``kernels.annealing.assignment_costs``, ``assigned_pairs``), the
    assignment SciPy's."""
    cost = annealing.assignment_costs(-np.log(np.maximum(A, 1e-300)))  # finite: A > 0
    rows, cols = linear_sum_assignment(cost)
    pairs, unmatched = annealing.assigned_pairs(
        rows.astype(np.int64), cols.astype(np.int64), cost, A.shape[1] - 1
    )
    return pairs, unmatched.tolist()


def _reference_anneal(Pm, unary, psi, psi_end, growth):
    """``reference.matching.anneal`` on the kernel's flattened P (g e, g e)."""
    g, e = unary.shape
    return ref_matching.anneal(np.reshape(Pm, (g, e, g, e)), unary, psi, psi_end, growth)


def _reference_prune_pairs(observed, catalog, pairs, weights, tol, min_matches):
    """``reference.matching.rigid_residual_check`` with the rejected blobs as an int64
    array, as ``kernels.residual_check.prune_pairs`` returns them."""
    kept, rejected, ok = ref_matching.rigid_residual_check(
        observed, catalog, pairs, weights, tol, min_matches
    )
    return kept, np.asarray(rejected, np.int64), ok


COMPILED = MatchingArithmetic(
    "compiled",
    annealing.pair_potentials,
    annealing.size_mismatch,
    annealing.anneal_assignment,
    annealing.soft_assignment,
    _compiled_one_to_one,
    residual_check.prune_pairs,
    triplets.catalog_triplets,
    triplets.triplet_search,
    triplets.trials_needed,
)
REFERENCE = MatchingArithmetic(
    "reference",
    ref_matching.pair_potentials,
    ref_matching.size_mismatch,
    _reference_anneal,
    ref_matching.soft_assignment,
    ref_matching.one_to_one,
    _reference_prune_pairs,
    ref_triplets.catalog_triplets,
    ref_triplets.triplet_search,
    ref_triplets.trials_needed,
)
