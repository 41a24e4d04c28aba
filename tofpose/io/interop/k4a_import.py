"""Azure Kinect recording (Matroska, ``k4arecorder``'s ``.mkv``) -> HDF5 recording
(``tofpose import k4a``; docs/interop.md, "Azure Kinect").

Decoded with PyAV (FFmpeg's Matroska demuxer), no Azure Kinect SDK. A recording holds
(Azure Kinect's "Recording file format"): a ``DEPTH`` and an ``IR`` track of 16-bit
big-endian pixels (``b16g``: PyAV's ``gray16be``) per capture, z depth in mm with 0 where
there is none and the active IR brightness (65535 where it saturates), a ``COLOR`` and an
``IMU`` track (not read), and the attachment ``calibration.json`` (the factory
calibration, ``k4a_calibration``). Block times are microseconds from the recording's
start; the tag ``K4A_START_OFFSET_NS`` added to them gives the device timestamps the SDK
reports, kept as each frame's ``time_s``.

A frame is the DEPTH and IR images of one capture (the same block time). The recording's
camera is the depth camera of the file's own calibration in its depth mode; the gray
image is the IR image as it is (uint16 counts, full scale 65535); the distance image is
the z depth converted to radial distance along each pixel's ray, NaN where the depth is
0. A truncated file (FFmpeg: "File ended prematurely") is an error, not fewer frames.
"""

from __future__ import annotations

import sys
from dataclasses import replace
from pathlib import Path

import av
import av.logging
import numpy as np
from tqdm import tqdm

from tofpose.core.camera import CameraModel
from tofpose.core.depth import decode_depth
from tofpose.io.interop.k4a_calibration import K4aCamera, depth_camera
from tofpose.io.recording import RecordingWriter

DEPTH_TRACK, IR_TRACK = "DEPTH", "IR"
CALIBRATION_ATTACHMENT = "calibration.json"
PIXEL_FORMAT = "gray16be"  # the tracks' b16g: 16-bit big-endian


class K4aImportError(ValueError):
    """An Azure Kinect recording that cannot become a recording: names the file and why."""


def _track(container: av.container.InputContainer, title: str, path: Path):
    """The video stream titled ``title`` (the recorder's track names); error listing them."""
    for s in container.streams.video:
        if s.metadata.get("title") == title:
            fmt = s.codec_context.format
            if s.codec_context.name != "rawvideo" or fmt is None or fmt.name != PIXEL_FORMAT:
                raise K4aImportError(
                    f"{path}: {title} track is {s.codec_context.name} "
                    f"{fmt.name if fmt else None}, expected rawvideo {PIXEL_FORMAT}"
                )
            return s
    titles = [s.metadata.get("title") for s in container.streams]
    raise K4aImportError(
        f"{path}: no {title} track (tracks: {titles}); record with depth and IR on "
        "(a passive-IR or colour-only recording has no frames for tofpose)"
    )


def _calibration(container: av.container.InputContainer, path: Path) -> bytes:
    for s in container.streams.attachments:
        if s.name == CALIBRATION_ATTACHMENT:
            return bytes(s.data)
    names = [s.name for s in container.streams.attachments]
    raise K4aImportError(f"{path}: no {CALIBRATION_ATTACHMENT} attachment (attachments: {names})")


def _image(packet: av.Packet, width: int, height: int, what: str, where: str) -> np.ndarray:
    """A block's 16-bit big-endian pixels -> (H, W) uint16 (PyAV decodes ``gray16be``)."""
    if packet.size != width * height * 2:
        raise K4aImportError(
            f"{where}: {what} image has {packet.size} bytes, a {width} x {height} "
            f"16-bit image has {width * height * 2}"
        )
    frames = packet.decode()
    if len(frames) != 1:
        raise K4aImportError(f"{where}: {what} block decodes to {len(frames)} images")
    return frames[0].to_ndarray().astype(np.uint16, copy=False)


def _errors(logs: list[tuple[int, str, str]]) -> list[str]:
    """FFmpeg's messages at level ERROR or worse (a truncated or corrupt file)."""
    return [msg.strip() for level, _name, msg in logs if level <= av.logging.ERROR]


def import_k4a(
    path: str | Path,
    out: str | Path,
    *,
    progress: bool = True,
    overwrite: bool = False,
) -> dict:
    """Write the depth/IR captures of the Azure Kinect recording ``path`` to ``out``.

    Returns {"frames": N, "camera": CameraModel, "lens_fit_max_px": float (the largest
    pixel error of the five-coefficient lens against the file's rational model over the
    mode's field)}. ``K4aImportError`` names the file and the problem: not a Matroska
    file, a track or the calibration missing, a frame of the wrong size, a capture
    with one of its two images, a truncated file.
    """
    path, out = Path(path), Path(out)
    if out.exists() and not overwrite:
        raise K4aImportError(f"{out} exists (pass --force to overwrite it)")
    if not path.is_file():
        raise K4aImportError(f"{path}: no such file")
    # FFmpeg reports a truncated file only in its log: capture it, every repeat included
    level, skip = av.logging.get_level(), av.logging.get_skip_repeated()
    av.logging.set_level(av.logging.ERROR)
    av.logging.set_skip_repeated(False)
    try:
        with av.logging.Capture(local=True) as logs:
            return _import(path, out, logs, progress)
    finally:
        av.logging.set_skip_repeated(skip)
        av.logging.set_level(level)


def _open(path: Path) -> av.container.InputContainer:
    try:
        return av.open(str(path), mode="r")
    except (av.error.FFmpegError, UnicodeDecodeError) as exc:
        raise K4aImportError(f"{path}: not a readable Matroska file ({exc})") from exc


def _camera(container: av.container.InputContainer, depth_s, ir_s, path: Path) -> K4aCamera:
    """The depth camera of the file's calibration in its DEPTH track's mode, named after
    the device; ``K4aImportError`` when the tracks' size is not the mode's."""
    mode = depth_s.metadata.get("K4A_DEPTH_MODE", "")
    try:
        k4a = depth_camera(_calibration(container, path), mode)
    except ValueError as exc:
        raise K4aImportError(f"{path}: {exc}") from exc
    serial = container.metadata.get("K4A_DEVICE_SERIAL_NUMBER")
    if serial:
        k4a = replace(k4a, camera=replace(k4a.camera, name=f"Azure Kinect {serial} {mode}"))
    size = (k4a.camera.width, k4a.camera.height)
    if (depth_s.width, depth_s.height) != size or (ir_s.width, ir_s.height) != size:
        raise K4aImportError(
            f"{path}: DEPTH {depth_s.width} x {depth_s.height} and IR {ir_s.width} x "
            f"{ir_s.height} images, depth mode {mode} has {size[0]} x {size[1]}"
        )
    return k4a


def _write_captures(
    container: av.container.InputContainer,
    tracks: tuple,
    camera: CameraModel,
    writer: RecordingWriter,
    path: Path,
    progress: bool,
) -> tuple[int, dict[int, str]]:
    """Append each capture (a DEPTH and an IR block at one block time) to ``writer``.
    Returns (captures written, {block time: track} of the blocks left without a partner)."""
    depth_s, ir_s = tracks
    offset_s = int(container.metadata.get("K4A_START_OFFSET_NS", "0")) * 1e-9
    pending: dict[int, tuple[str, np.ndarray]] = {}
    frames = 0
    bar = tqdm(desc="import k4a", unit="frame", disable=not progress, file=sys.stderr)
    for packet in container.demux(depth_s, ir_s):
        if packet.pts is None or packet.size == 0:  # the demuxer's end-of-stream
            continue
        what = DEPTH_TRACK if packet.stream is depth_s else IR_TRACK
        time_s = float(packet.pts * packet.time_base) + offset_s
        where = f"{path} at {time_s:.6f} s"
        image = _image(packet, camera.width, camera.height, what, where)
        other = pending.pop(packet.pts, None)
        if other is None:
            pending[packet.pts] = (what, image)
            continue
        if other[0] == what:
            raise K4aImportError(f"{where}: two {what} images in one capture")
        depth, ir = (image, other[1]) if what == DEPTH_TRACK else (other[1], image)
        writer.append(ir, decode_depth(depth, camera), time_s)
        frames += 1
        bar.update(1)
    bar.close()
    return frames, {pts: what for pts, (what, _) in pending.items()}


def _import(path: Path, out: Path, logs: list, progress: bool) -> dict:
    container = _open(path)
    with container:
        if "matroska" not in container.format.name:
            raise K4aImportError(f"{path}: a {container.format.name} file, not Matroska (.mkv)")
        depth_s, ir_s = _track(container, DEPTH_TRACK, path), _track(container, IR_TRACK, path)
        k4a = _camera(container, depth_s, ir_s, path)
        camera = k4a.camera
        partial = out.with_name(out.name + ".partial")  # renamed when complete
        # stored radial: decode_depth converts the device's z (distance_kind "z")
        writer = RecordingWriter(partial, replace(camera, distance_kind="radial"))
        try:
            frames, pending = _write_captures(
                container, (depth_s, ir_s), camera, writer, path, progress
            )
            errors = _errors(logs)
            if errors:
                raise K4aImportError(
                    f"{path}: the file is truncated or corrupt (FFmpeg: {'; '.join(errors)}); "
                    f"{frames} complete captures before the damage"
                )
            if pending:
                pts = min(pending)
                offset_s = int(container.metadata.get("K4A_START_OFFSET_NS", "0")) * 1e-9
                time_s = float(pts * depth_s.time_base) + offset_s
                raise K4aImportError(
                    f"{path}: {len(pending)} captures with only one of DEPTH and IR "
                    f"(the first at {time_s:.6f} s has only {pending[pts]}): a truncated "
                    "file, or a track the recorder dropped"
                )
            if frames == 0:
                raise K4aImportError(f"{path}: no capture with both DEPTH and IR images")
        except BaseException:
            writer.close()
            partial.unlink(missing_ok=True)
            raise
        writer.close()
        partial.replace(out)
    return {"frames": frames, "camera": camera, "lens_fit_max_px": k4a.lens_fit.max_error_px}
