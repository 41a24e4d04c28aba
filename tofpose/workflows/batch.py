"""``tofpose study``, ``reprocess`` and ``compare``: the Dask work of ``tofpose.study`` and
``tofpose.batch`` with the console summary of each; each returns the command's exit
code (2 for a refused input, 130 for an interrupted study)."""

from __future__ import annotations

import json
import sys
from pathlib import Path

from tofpose.io.camera_file import read_text_file
from tofpose.io.recording import RecordingError


def study(args) -> int:
    """``tofpose study``: print the example spec, or run a spec into --out."""
    from tofpose.batch.cluster import ClusterError
    from tofpose.study.run import StudyCancelledError, run_study
    from tofpose.study.spec import EXAMPLE, StudySpec, StudySpecError
    from tofpose.study.store import StudyStoreError

    if args.example:
        print(json.dumps(EXAMPLE, indent=2))
        return 0
    if not args.spec or not args.out:
        print("tofpose study: give a SPEC and --out DIR (or --example)", file=sys.stderr)
        return 2
    try:
        spec = StudySpec.from_json(read_text_file(args.spec, "study spec"), args.spec)
        summary = run_study(spec, args.out, workers=args.workers, scheduler=args.scheduler)
    except (StudySpecError, StudyStoreError, ClusterError) as exc:
        print(f"tofpose study: {exc}", file=sys.stderr)
        return 2
    except (KeyboardInterrupt, StudyCancelledError):
        print(
            f"tofpose study: interrupted; {args.out} holds the chunks that finished "
            "(study.json: incomplete); run the same command again to resume",
            file=sys.stderr,
        )
        return 130
    a = summary["all"]
    print(summary["verdict"]["text"])
    print(
        f"{summary['frames_stored']} frames in {len(spec.cells)} cells: gross success "
        f"{a['success_pct']:.1f} %, {a['wrong']} wrong, {a['confidently_wrong']} confidently "
        f"wrong -> {Path(args.out) / 'report.html'}"
    )
    return 0


def reprocess(args) -> int:
    """``tofpose reprocess``: recordings in chunks on Dask, one CSV each."""
    from tofpose.batch.cluster import ClusterError
    from tofpose.batch.reprocess import ReprocessError, Settings
    from tofpose.batch.reprocess import reprocess as run

    settings = Settings(
        args.camera,
        args.catalog,
        args.tracking,
        pixel_fit=args.pixel_fit,
        learn_range_bias=args.learn_range_bias,
    )
    try:
        s = run(
            args.recordings,
            args.out,
            settings=settings,
            workers=args.workers,
            scheduler=args.scheduler,
            filter_state=args.filter,
            causal_filter=args.causal,
            chunk_frames=args.chunk_frames,
        )
    except (RecordingError, ReprocessError, ClusterError) as exc:
        print(f"tofpose reprocess: {exc}", file=sys.stderr)
        return 2
    for r in s["recordings"]:
        print(f"{r['ok']}/{r['frames']} frames with a pose -> {Path(args.out) / r['csv']}")
    fps = s["run"]["frames_per_s"]
    print(f"{s['run']['frames']} frames on {s['run']['workers']} workers, {fps:.1f} frames/s")
    return 0


def compare(args) -> int:
    """``tofpose compare``: two runs' poses frame by frame."""
    from tofpose.batch.compare import CompareError, compare_runs

    try:
        s = compare_runs(args.run_a, args.run_b, args.out)
    except CompareError as exc:
        print(f"tofpose compare: {exc}", file=sys.stderr)
        return 2
    for name, r in s["recordings"].items():
        att, pos = r["attitude_diff_deg"], r["position_diff_mm"]
        print(
            f"{name}: {r['frames']} frames, poses {r['ok_a']} -> {r['ok_b']} "
            f"(gained {r['gained']}, lost {r['lost']}); attitude difference p50 "
            f"{att['p50']} / max {att['max']} deg, position p50 {pos['p50']} / max "
            f"{pos['max']} mm"
        )
    print(f"-> {Path(args.out) / 'compare.json'}")
    return 0
