"""The ``tofpose`` command: estimate poses from recordings, simulate, render, demo, and
the server's commands.

This module is the parser only: each command's work is a function of
``tofpose.workflows`` (imported when the command runs, so ``tofpose --help`` starts at
once). The server's commands (``serve``, ``report``, ``keys``, ``record``, ``emulate``,
``openapi``) are not the library's: the server package registers them in the entry-point
group ``tofpose.commands`` (``COMMAND_GROUP``), each an object with ``name``,
``add_parser(subparsers)`` and ``run(options) -> int``; the library never imports it.
"""

from __future__ import annotations

import argparse
import sys
from importlib.metadata import entry_points
from pathlib import Path
from typing import Any, Protocol

from tofpose.io.interop import DEFAULT_MCAP_PROFILE, MCAP_PROFILES

#: the entry-point group of commands that other packages add to ``tofpose``
COMMAND_GROUP = "tofpose.commands"


class Command(Protocol):
    """A subcommand another package adds (entry-point group ``tofpose.commands``)."""

    name: str

    def add_parser(self, subparsers: Any) -> None: ...

    def run(self, options: dict[str, Any]) -> int: ...


def registered_commands() -> dict[str, Command]:
    """The commands of the entry-point group, by name (loading one imports only its
    parser module; its ``run`` imports the rest). A command whose package cannot be
    imported (the library installed without the server) is left out, so the library's
    own commands still run."""
    commands: dict[str, Command] = {}
    for ep in entry_points(group=COMMAND_GROUP):
        try:
            command = ep.load()
        except ImportError:
            continue
        commands[command.name] = command
    return commands


def _cluster_arguments(p: argparse.ArgumentParser) -> None:
    g = p.add_mutually_exclusive_group()
    g.add_argument(
        "--workers",
        type=int,
        help="worker processes of a LocalCluster on this machine (default: its cores)",
    )
    g.add_argument("--scheduler", help="address of a running Dask scheduler, tcp://host:8786")


def _pixel_fit_argument(p) -> None:
    """``--pixel-fit`` / ``--no-pixel-fit`` (estimate's and reprocess')."""
    p.add_argument(
        "--pixel-fit",
        action=argparse.BooleanOptionalAction,
        default=None,
        help="refine each pose on the markers' raw pixels, the pose and covariance of the "
        "sensor's model (default: on, unless --camera's JSON carries a covariance scale "
        "from calibrate-covariance, which calibrates the centroid pose's covariance; "
        "docs/algorithm.md, 'Pixel-level fit'); --no-pixel-fit: the centroid pose only, "
        "10-50x faster a frame at a cost in accuracy (docs/results.md)",
    )


def _range_bias_argument(p) -> None:
    """``--learn-range-bias`` / ``--no-learn-range-bias`` (estimate's and reprocess')."""
    p.add_argument(
        "--learn-range-bias",
        action=argparse.BooleanOptionalAction,
        default=None,
        help="learn the mean and spread of the camera's range offsets over up to 64 of the "
        "recording's frames first, and measure every frame with them as the offset's "
        "prior (default: with the pixel fit, whose offset likelihoods are the sensor "
        "model's own; the centroid pose's are too wide to learn the spread from); "
        "--no-learn-range-bias: the configured prior (15 mm without a range "
        "calibration). A camera JSON with a covariance scale keeps the configured prior "
        "either way (the scale was fitted with it). docs/algorithm.md, 'Range bias "
        "learned over a recording'",
    )


def _add_measurement_commands(sub) -> None:
    """The subcommands estimate, calibrate-range and calibrate-covariance, on ``sub``."""
    p = sub.add_parser("estimate", help="estimate the pose of every frame of a recording")
    p.add_argument("recording")
    p.add_argument(
        "--catalog",
        help="built-in catalog name (paper-target) or catalog JSON (default: the recording's)",
    )
    p.add_argument("--camera", help="camera JSON or camera profile name (default: the recording's)")
    p.add_argument("--out", required=True, help="output CSV")
    p.add_argument(
        "--tracking",
        action="store_true",
        help="tracking mode: look for reflectors near their last position",
    )
    p.add_argument(
        "--filter",
        action="store_true",
        help="add the relative-state filter's angular rate and velocity with "
        "their 1-sigma (rate_*, vel_*, sigma_rate_*, sigma_vel_*), each frame's from all "
        "the recording's poses (a smoother: no start-up, no lag); each pose is then "
        "measured on its own frame (frames combined over time lag a moving target)",
    )
    p.add_argument(
        "--causal",
        action="store_true",
        help="with --filter: each frame's state from the poses up to it only, as the live "
        "loop has it (it starts with the rate unknown and lags a changing rate)",
    )
    _pixel_fit_argument(p)
    _range_bias_argument(p)
    p = sub.add_parser(
        "calibrate-range",
        help="fit the camera's range correction from a recording of the known target",
    )
    p.add_argument("recording")
    p.add_argument("--out", required=True, help="camera JSON with its range_correction")
    p.add_argument(
        "--reference",
        choices=("truth", "reference", "lab_truth"),
        default="truth",
        help="pose per frame to fit against: truth (/truth, the pose a simulator rendered; "
        "default) or reference (/reference, the lab's encoders + geometry; lab_truth is "
        "its older name)",
    )
    p.add_argument(
        "--modulation-mhz",
        type=float,
        default=None,
        help="the recording's modulation frequency (default: its camera's, 6 MHz on "
        "recordings that do not state one)",
    )
    p = sub.add_parser(
        "calibrate-covariance",
        help="fit the camera's covariance factor per range from a recording of the known target",
    )
    p.add_argument("recording")
    p.add_argument("--out", required=True, help="camera JSON with its covariance_scale")
    p.add_argument(
        "--camera",
        help="camera JSON to start from, e.g. with its range correction "
        "(default: the recording's camera)",
    )
    p.add_argument(
        "--reference",
        choices=("truth", "reference", "lab_truth"),
        default="truth",
        help="pose per frame to fit against: truth (/truth, the pose a simulator rendered; "
        "default) or reference (/reference, the lab's; lab_truth is its older name); its "
        "own error must be well below the pose's",
    )
    p.add_argument(
        "--knots-mm",
        type=lambda v: [float(x) for x in v.split(",")],
        help="target distances of the factors, comma separated (default: every "
        "1.5x over the recording's range, each with >= 20 frames)",
    )


def _add_simulation_commands(sub) -> None:
    """The subcommands simulate, render, demo, on the subparsers ``sub``."""
    p = sub.add_parser("simulate", help="write a simulated recording with ground truth")
    p.add_argument("--scenario", required=True)
    p.add_argument("--frames", type=int, required=True)
    p.add_argument("--out", required=True)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument(
        "--catalog", help="built-in catalog name (paper-target) or catalog JSON (default: it)"
    )
    p.add_argument(
        "--camera",
        help="camera profile (tofcam660, azure-kinect-nfov, hololens2-ahat) or camera JSON "
        "to render through (default: tofcam660; docs/devices.md)",
    )
    p = sub.add_parser("render", help="write gray and distance PNGs of a scenario frame")
    p.add_argument("--scenario", default="stability-697")
    p.add_argument("--out-prefix", required=True)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--camera", help="camera profile or camera JSON (default: tofcam660)")
    p = sub.add_parser("demo", help="simulate, estimate and print estimate vs truth")
    p.add_argument("--frames", type=int, default=48)


def _add_interop_commands(sub) -> None:
    """The subcommands export and import, on the subparsers ``sub``."""
    p = sub.add_parser("export", help="write a recording in another format (docs/interop.md)")
    p.add_argument(
        "format",
        choices=("mcap", "rrd"),
        help="mcap: Foxglove / ROS 2 / Rerun; rrd: Rerun's own format, with the pose's time "
        "series and the image overlay (needs rerun-sdk)",
    )
    p.add_argument("recording")
    p.add_argument("--out", required=True, help="output file (REC.mcap, REC.rrd)")
    p.add_argument(
        "--no-viewers",
        dest="viewers",
        action="store_false",
        help="mcap: do not write the Foxglove layout and the Rerun blueprint beside the "
        "file (REC.foxglove-layout.json, REC.rbl; an .rrd carries its blueprint)",
    )
    p.add_argument(
        "--profile",
        choices=MCAP_PROFILES,
        default=DEFAULT_MCAP_PROFILE,
        help="foxglove: Foxglove's schemas, mm (default; Foxglove, Rerun, `import mcap`); "
        "ros2: ROS 2 messages (cdr), m and rad, REP 103 frames (ros2 bag, rosbags)",
    )
    p.add_argument(
        "--catalog",
        help="built-in catalog name (paper-target) or catalog JSON (default: the recording's)",
    )
    p.add_argument("--camera", help="camera JSON or camera profile name (default: the recording's)")
    p.add_argument("--tracking", action="store_true", help="estimate in tracking mode")
    p.add_argument(
        "--no-estimate",
        dest="estimate",
        action="store_false",
        help="frames and reference poses only, no pipeline run",
    )
    p.add_argument(
        "--no-previews",
        dest="previews",
        action="store_false",
        help="leave out the viewer images (/tof/gray_preview, /tof/distance_preview): "
        "a smaller file (the foxglove profile; ros2 has none)",
    )
    p.add_argument("--force", action="store_true", help="overwrite --out")
    p = sub.add_parser("import", help="make a recording from another format (docs/interop.md)")
    p.add_argument(
        "format",
        choices=("mcap", "ros2", "k4a"),
        help="mcap: our (Foxglove-schema) MCAP export; ros2: a ROS 2 bag (MCAP or sqlite3); "
        "k4a: an Azure Kinect recording (.mkv)",
    )
    p.add_argument("file", help="input file (REC.mcap, a ROS 2 bag directory, REC.mkv)")
    p.add_argument("--out", required=True, help="output recording (REC.h5)")
    p.add_argument("--gray-topic", help="mcap: gray image topic (default /tof/gray)")
    p.add_argument("--distance-topic", help="mcap: distance image topic (default /tof/distance)")
    p.add_argument(
        "--image",
        help="ros2: amplitude/IR sensor_msgs/Image topic (default /tofpose/camera/amplitude)",
    )
    p.add_argument(
        "--depth", help="ros2: depth sensor_msgs/Image topic (default /tofpose/camera/depth)"
    )
    p.add_argument(
        "--camera-info",
        help="ros2: sensor_msgs/CameraInfo topic (default: camera_info beside --image, "
        "else the bag's only one)",
    )
    p.add_argument(
        "--depth-kind",
        choices=("z", "radial"),
        help="ros2: what --depth holds (default: z, REP 118; radial for /tofpose/camera/distance)",
    )
    p.add_argument(
        "--camera",
        help="ros2: camera profile or camera JSON giving the device's full scale, count "
        "scale and range (default: tofcam660); K and D come from the bag",
    )
    p.add_argument("--force", action="store_true", help="overwrite --out")


def _add_batch_commands(sub) -> None:
    """The subcommands study, reprocess, compare, warm-up, on the subparsers ``sub``."""
    p = sub.add_parser(
        "study",
        help="Monte-Carlo accuracy study over a grid of cells, on Dask (docs/scaleout.md)",
    )
    p.add_argument("spec", nargs="?", help="study spec JSON (tofpose study --example prints one)")
    p.add_argument("--out", help="study directory (created; a run of the same spec resumes)")
    p.add_argument("--example", action="store_true", help="print a small example spec and exit")
    _cluster_arguments(p)
    p = sub.add_parser(
        "reprocess",
        help="re-run the pipeline over recordings in chunks on Dask; CSVs as estimate's",
    )
    p.add_argument("recordings", nargs="+", metavar="REC.h5")
    p.add_argument("--out", required=True, help="output directory: <recording>.csv each")
    p.add_argument(
        "--camera", help="camera JSON or camera profile name (default: each recording's)"
    )
    p.add_argument(
        "--catalog",
        help="built-in catalog name (paper-target) or catalog JSON (default: each recording's)",
    )
    p.add_argument("--tracking", action="store_true", help="the pipeline's tracking mode")
    p.add_argument(
        "--filter",
        action="store_true",
        help="add the relative-state filter's columns (poses from single frames, as "
        "estimate --filter)",
    )
    p.add_argument(
        "--causal",
        action="store_true",
        help="with --filter: each frame's state from the poses up to it (estimate --causal)",
    )
    p.add_argument("--chunk-frames", type=int, default=512, help="frames per task (default 512)")
    _pixel_fit_argument(p)
    _range_bias_argument(p)
    _cluster_arguments(p)
    p = sub.add_parser(
        "compare", help="compare two runs of estimate/reprocess: per-frame pose differences"
    )
    p.add_argument("run_a", help="a CSV, or a reprocess directory")
    p.add_argument("run_b", help="a CSV, or a reprocess directory")
    p.add_argument("--out", required=True, help="output directory (compare.csv/json/png)")
    sub.add_parser(
        "warm-up",
        help="compile the pipeline's kernels into numba's cache (once after installing)",
    )


def build_parser(commands: dict[str, Command] | None = None) -> argparse.ArgumentParser:
    """The ``tofpose`` command line: every subcommand and its options, the registered
    ones (``registered_commands()`` unless given) included."""
    ap = argparse.ArgumentParser(prog="tofpose", description=__doc__.split("\n\n")[0])
    ap.add_argument("--version", action="version", version=f"%(prog)s {_version()}")
    sub = ap.add_subparsers(dest="cmd", required=True)
    for add in (
        _add_measurement_commands,
        _add_simulation_commands,
        _add_interop_commands,
        _add_batch_commands,
    ):
        add(sub)
    for command in (registered_commands() if commands is None else commands).values():
        command.add_parser(sub)
    return ap


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("tofpose")
    except PackageNotFoundError:
        return "(not installed)"


def _run_batch(args: argparse.Namespace) -> int | None:
    """The Dask commands and the kernel warm-up (their own error handling); None for
    the others."""
    if args.cmd in ("study", "reprocess", "compare"):
        from tofpose.workflows import batch

        return {"study": batch.study, "reprocess": batch.reprocess, "compare": batch.compare}[
            args.cmd
        ](args)
    if args.cmd == "warm-up":
        from tofpose.core.compiled import kernel_cache_dir, prune_stale_kernel_caches
        from tofpose.warmup import warm_up

        print(f"pipeline kernels ready in {warm_up():.1f} s ({kernel_cache_dir()})")
        for old in prune_stale_kernel_caches():
            print(f"removed the stale kernel cache {old}")
        return 0
    return None


def _run_library(args: argparse.Namespace) -> int:
    """estimate, export, import, calibrate-*, simulate, render, demo."""
    from tofpose.workflows import interop, measurement, simulation

    if args.cmd == "estimate":
        s = measurement.estimate(
            args.recording,
            args.out,
            args.catalog,
            args.camera,
            tracking=args.tracking,
            filter_state=args.filter,
            pixel_fit=args.pixel_fit,
            causal_filter=args.causal,
            learn_range_bias=args.learn_range_bias,
        )
        if s["range_bias"]:
            print(s["range_bias"])
        print(f"{s['ok']}/{s['frames']} frames with a pose -> {args.out}")
    elif args.cmd == "export":
        print(interop.export_file(args))
    elif args.cmd == "import":
        print(interop.import_file(args))
    elif args.cmd == "calibrate-covariance":
        print(
            measurement.calibrate_covariance(
                args.recording, args.out, args.camera, args.reference, args.knots_mm
            )
        )
    elif args.cmd == "calibrate-range":
        print(
            measurement.calibrate_range(
                args.recording, args.out, args.reference, args.modulation_mhz
            )
        )
    elif args.cmd == "simulate":
        if args.frames < 1:
            raise SystemExit("tofpose: --frames must be >= 1")
        simulation.simulate(
            args.scenario, args.frames, args.out, args.seed, args.catalog, camera_arg=args.camera
        )
        print(f"wrote {args.frames} frames -> {args.out}")
    elif args.cmd == "render":
        for path in simulation.render_pngs(
            args.scenario, args.out_prefix, args.seed, camera_arg=args.camera
        ):
            print(path)
    elif args.cmd == "demo":
        return simulation.demo(args.frames)
    return 0


#: the library's commands whose ``--out`` (or ``--out-prefix``) is a file to write; its
#: directory must exist (study, reprocess and compare make their output directory)
FILE_OUTPUTS = (
    "estimate",
    "calibrate-range",
    "calibrate-covariance",
    "simulate",
    "render",
    "export",
    "import",
)


def output_directory_error(args: argparse.Namespace) -> str | None:
    """A sentence naming the missing directory of a command's output file, or None."""
    if args.cmd not in FILE_OUTPUTS:
        return None
    out = getattr(args, "out", None) or getattr(args, "out_prefix", None)
    if out is None:
        return None
    parent = Path(out).expanduser().parent
    if parent.is_dir():
        return None
    what = "is a file, not a directory" if parent.exists() else "does not exist"
    return f"tofpose {args.cmd}: the output's directory {str(parent)!r} {what}: {out}"


def main(argv: list[str] | None = None) -> int:
    from tofpose.core.threads import single_threaded_blas

    single_threaded_blas()  # idle BLAS threads would burn a core
    commands = registered_commands()
    args = build_parser(commands).parse_args(argv)
    if args.cmd in commands:
        opts = vars(args)
        return commands[opts.pop("cmd")].run(opts)
    missing = output_directory_error(args)
    if missing is not None:
        print(missing, file=sys.stderr)
        return 2
    code = _run_batch(args)
    if code is not None:
        return code
    from tofpose.io.recording import RecordingError

    try:
        return _run_library(args)
    except (RecordingError, ValueError) as exc:
        print(f"tofpose: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
