"""The selection of the pipeline's arithmetic: one record per implementation, made of
each stage's own (``tofpose.stages.<stage>.arithmetic``).

``COMPILED`` runs the compiled kernels (``tofpose/stages/<stage>/kernels/``), ``REFERENCE``
their plain NumPy/SciPy statements (``tofpose/stages/<stage>/reference/``).
``PosePipeline(..., implementation="reference")`` runs the whole chain on ``REFERENCE``:
the reference is then both the kernels' test oracle and an A/B baseline of the pipeline.
Each stage's field has one calling convention, the kernel's; where a reference function
has another form, a small adapter in the stage's ``arithmetic`` module gives it the
kernel's (the reference packages stay free of the pipeline's records).

Not covered (the reference path still runs compiled code there): the frame check's
float32 conversion (``extraction.check_frame``: ``kernels.levels.checked_frame``,
``clean_distance``), the persistence history's pixel masks (``persistence.Persistence.
commit``: ``kernels.persistence.pixel_mask``) and the ``CameraModel`` records built once
at construction (``camera_record``'s pixel bearings).
"""

from __future__ import annotations

from dataclasses import dataclass

from tofpose.stages.ellipses import arithmetic as ellipses
from tofpose.stages.extraction import arithmetic as extraction
from tofpose.stages.matching import arithmetic as matching
from tofpose.stages.persistence import arithmetic as persistence
from tofpose.stages.pose import arithmetic as pose
from tofpose.stages.tracking import arithmetic as tracking

#: the names ``PosePipeline(implementation=...)`` accepts
IMPLEMENTATIONS = ("compiled", "reference")


@dataclass(frozen=True)
class Arithmetic:
    """Every stage's arithmetic in one implementation (``name``)."""

    name: str
    extraction: extraction.ExtractionArithmetic
    ellipses: ellipses.EllipsesArithmetic
    persistence: persistence.PersistenceArithmetic
    matching: matching.MatchingArithmetic
    pose: pose.PoseArithmetic
    tracking: tracking.TrackingArithmetic


_STAGES = (extraction, ellipses, persistence, matching, pose, tracking)
COMPILED = Arithmetic("compiled", *(s.COMPILED for s in _STAGES))
REFERENCE = Arithmetic("reference", *(s.REFERENCE for s in _STAGES))


def arithmetic_for(implementation: str) -> Arithmetic:
    """``COMPILED`` for "compiled", ``REFERENCE`` for "reference"; ``ValueError`` naming
    the accepted values otherwise."""
    for a in (COMPILED, REFERENCE):
        if implementation == a.name:
            return a
    raise ValueError(
        f"unknown implementation {implementation!r}: expected one of "
        + ", ".join(repr(n) for n in IMPLEMENTATIONS)
    )
