"""A small simulated recording with truth and lab truth, exported to MCAP once per module."""

from __future__ import annotations

import pytest

from tofpose.cli import main


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    """An 8-frame simulated recording with /truth and /lab_truth (the realistic scene:
    blobs rejected by gates, an unmatched candidate and one frame without a pose)."""
    path = tmp_path_factory.mktemp("rec") / "rec.h5"
    assert (
        main(
            [
                "simulate",
                "--scenario",
                "realistic",
                "--frames",
                "8",
                "--out",
                str(path),
                "--seed",
                "3",
            ]
        )
        == 0
    )
    return path


@pytest.fixture(scope="module")
def exported(recording):
    """``recording`` exported with the pipeline's estimates (``tofpose export mcap``)."""
    out = recording.with_suffix(".mcap")
    assert main(["export", "mcap", str(recording), "--out", str(out)]) == 0
    return out
