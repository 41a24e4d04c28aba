"""An emulator of a three-axis rate-table controller in the style of Acutronic's ACUTROL3000,
speaking SCPI over a raw TCP socket (the way ``TCPIP::host::port::SOCKET`` instruments are
driven), backed by the simulated turntable of a ``SimWorld``.

The command set is documented in docs/devices.md ("Rate-table protocol"). In short:
axes are numbered 1 (outer, yaw), 2 (middle, pitch), 3 (inner, roll), 4 (rail, mm);
an axis moves on ``:DEMand:POSition n,value`` only in position mode (``:MODE n,POS``)
with its interlock closed (``:INTerlock:CLOSe n``), no fault, and the safety interlock
closed; ``:ABORt`` stops every axis at once. Errors go to the session's SCPI error queue
(``:SYSTem:ERRor?``), as SCPI instruments do. Faults and the safety interlock can be
injected (``inject_fault``, ``set_safety_open`` or the emulator-only ``:SIMulate:...``
commands), so that a driver's refusal and recovery paths can be tested.

Synthesis mode (``:MODE n,SYNThesis``), as rate-table controllers offer it beside position
and rate modes: the controller generates the axis' demand from a loaded function, a sine
(``:SYNThesis:SINE n,amplitude,frequency,cycles``) or a constant-rate ramp
(``:SYNThesis:RAMP n,rate,acceleration,hold``), started about the axis' position by
``:SYNThesis:STARt n`` (tofpose.lab.motion_profile gives both shapes). A controller made with
``synthesis=False`` has none of it (an older command set), so a driver's refusal can be
tested.
"""

from __future__ import annotations

import logging
import socketserver
import threading
from collections import deque
from dataclasses import dataclass

import numpy as np

from backend.drivers.sim import SimWorld
from backend.emulators.scpi_parse import ParsedCommand, ScpiError, parse_command, split_message
from backend.emulators.tcp import ServedEmulator, TrackedHandler, TrackedTCPServer
from tofpose import __version__
from tofpose.lab.motion_profile import MotionProfile, RampProfile, SineProfile
from tofpose.sim.turntable import AxisBusyError, SoftLimitError

log = logging.getLogger(__name__)

AXIS_NAMES = {1: "yaw", 2: "pitch", 3: "roll", 4: "rail"}
IDN = f"tofpose,ACUTROL3000 emulator,0,{__version__}"
MAX_ERROR_QUEUE = 16
MAX_LINE_BYTES = 4096

# :STATus? n bits
STATUS_INTERLOCK_CLOSED = 1
STATUS_IN_MOTION = 2
STATUS_IN_POSITION = 4
STATUS_FAULT = 8
STATUS_SAFETY_OPEN = 16
STATUS_ABORTED = 32

# Device-specific SCPI error codes (positive, as SCPI reserves negatives).
ERR_INTERLOCK_OPEN = 201
ERR_SAFETY_OPEN = 202
ERR_AXIS_FAULT = 203
ERR_NOT_POSITION_MODE = 204
ERR_NOT_SYNTHESIS_MODE = 205
ERR_NO_FUNCTION = 206
ERR_FUNCTION_RUNNING = 207

TREE: dict[tuple[str, ...], str] = {
    ("SYSTem", "ERRor"): "system_error",
    ("MODE",): "mode",
    ("DEMand", "POSition"): "demand_position",
    ("READ", "POSition"): "read_position",
    ("INTerlock",): "interlock",
    ("INTerlock", "CLOSe"): "interlock_close",
    ("INTerlock", "OPEN"): "interlock_open",
    ("ABORt",): "abort",
    ("STATus",): "status",
    ("FAULt",): "fault",
    ("FAULt", "CLEar"): "fault_clear",
    ("LIMit", "POSition", "LOW"): "limit_low",
    ("LIMit", "POSition", "HIGH"): "limit_high",
    ("LIMit", "VELocity"): "limit_velocity",
    ("LIMit", "ACCeleration"): "limit_acceleration",
    ("UNIT",): "unit",
    ("SIMulate", "SAFEty"): "simulate_safety",
    ("SIMulate", "FAULt"): "simulate_fault",
    ("SYNThesis",): "synthesis",
    ("SYNThesis", "SINE"): "synthesis_sine",
    ("SYNThesis", "RAMP"): "synthesis_ramp",
    ("SYNThesis", "STARt"): "synthesis_start",
    ("SYNThesis", "STATus"): "synthesis_status",
}
SYNTHESIS_NODE = "SYNThesis"


@dataclass
class _Axis:
    name: str
    mode: str = "OFF"  # OFF | POS | SYNT
    interlock_closed: bool = False
    fault: str | None = None
    low: float = 0.0
    high: float = 0.0
    function: MotionProfile | None = None  # loaded for synthesis mode


class _Session:
    """One client connection: its own SCPI error queue."""

    def __init__(self) -> None:
        self.errors: deque[ScpiError] = deque()

    def push(self, err: ScpiError) -> None:
        if len(self.errors) >= MAX_ERROR_QUEUE:
            self.errors[-1] = ScpiError(-350, "Queue overflow")
        else:
            self.errors.append(err)


class RateTableController:
    """The controller's logic (no sockets): ``execute(session, line)`` returns the reply
    line or None. Thread-safe: sessions run in their own threads. ``synthesis=False``
    models a controller without synthesis mode (its ``:SYNThesis`` commands are undefined
    headers)."""

    def __init__(self, world: SimWorld, *, synthesis: bool = True) -> None:
        self.world = world
        self.synthesis = synthesis
        self.tree = {p: h for p, h in TREE.items() if synthesis or p[0] != SYNTHESIS_NODE}
        tt_axes = world.bench.turntable.axes
        self.axes = {
            n: _Axis(name, low=tt_axes[name].min_pos, high=tt_axes[name].max_pos)
            for n, name in AXIS_NAMES.items()
            if name in tt_axes
        }
        self.safety_open = False
        self.aborted = False
        self._lock = threading.RLock()

    # -- injection (tests, the lab CLI) -------------------------------------------------
    def set_safety_open(self, is_open: bool) -> None:
        """Open (True) or close the safety interlock. Opening it aborts every axis and opens
        every axis interlock, as a safety chain drops the drives."""
        with self._lock:
            self.safety_open = is_open
            if is_open:
                self._abort_all()
                for ax in self.axes.values():
                    ax.interlock_closed = False

    def inject_fault(self, axis: int, text: str = "amplifier fault") -> None:
        """Fault one axis: every axis stops, that axis's interlock opens."""
        with self._lock:
            ax = self._axis_of(str(axis))
            ax.fault = text
            ax.interlock_closed = False
            self._abort_all()

    def _abort_all(self) -> None:
        self.world.stop()
        self.aborted = True

    # -- dispatch -----------------------------------------------------------------------
    def execute(self, session: _Session, line: str) -> str | None:
        replies = []
        for text in split_message(line):
            try:
                cmd = parse_command(text, self.tree)
                with self._lock:
                    reply = self._dispatch(session, cmd)
            except ScpiError as err:
                session.push(err)
                continue
            except Exception as exc:  # a bug must not kill the session
                log.exception("rate-table emulator: %s", text)
                session.push(ScpiError(-200, f"Execution error; {exc}"))
                continue
            if reply is not None:
                replies.append(reply)
        return ";".join(replies) if replies else None

    def _dispatch(self, session: _Session, cmd: ParsedCommand) -> str | None:
        if cmd.common:
            return self._common(session, cmd)
        handler = getattr(self, "_" + TREE_BY_PATH[cmd.path])
        return handler(session, cmd)

    def _common(self, session: _Session, cmd: ParsedCommand) -> str | None:
        name = cmd.path[0]
        if name == "*IDN" and cmd.query:
            return IDN
        if name == "*OPC" and cmd.query:
            return "1"
        if name == "*CLS" and not cmd.query:
            session.errors.clear()
            return None
        if name == "*RST" and not cmd.query:
            self._abort_all()
            for ax in self.axes.values():
                ax.mode, ax.interlock_closed, ax.function = "OFF", False, None
            return None
        raise ScpiError(-113, f"Undefined header; {name}{'?' if cmd.query else ''}")

    # -- helpers ------------------------------------------------------------------------
    def _axis_of(self, text: str) -> _Axis:
        try:
            n = int(text)
        except ValueError:
            raise ScpiError(
                -104, f"Data type error; axis must be an integer, got {text!r}"
            ) from None
        if n not in self.axes:
            raise ScpiError(-222, f"Data out of range; no axis {n} (axes {sorted(self.axes)})")
        return self.axes[n]

    @staticmethod
    def _want_args(cmd: ParsedCommand, n: int) -> tuple[str, ...]:
        if len(cmd.args) < n:
            raise ScpiError(-109, "Missing parameter")
        if len(cmd.args) > n:
            raise ScpiError(-108, "Parameter not allowed")
        return cmd.args

    def _axis_arg(self, cmd: ParsedCommand, n_args: int = 1) -> tuple[_Axis, tuple[str, ...]]:
        args = self._want_args(cmd, n_args)
        return self._axis_of(args[0]), args[1:]

    @staticmethod
    def _number(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            raise ScpiError(-104, f"Data type error; expected a number, got {text!r}") from None
        if not np.isfinite(value):
            raise ScpiError(-222, f"Data out of range; {text!r} is not finite")
        return value

    @staticmethod
    def _no_query(cmd: ParsedCommand) -> None:
        if cmd.query:
            raise ScpiError(-113, "Undefined header; this command has no query form")

    @staticmethod
    def _query_only(cmd: ParsedCommand) -> None:
        if not cmd.query:
            raise ScpiError(-113, "Undefined header; this is a query only (append ?)")

    # -- handlers -----------------------------------------------------------------------
    def _system_error(self, session: _Session, cmd: ParsedCommand) -> str:
        self._query_only(cmd)
        if not session.errors:
            return '0,"No error"'
        err = session.errors.popleft()
        return f'{err.code},"{err.message}"'

    def _mode(self, session: _Session, cmd: ParsedCommand) -> str | None:
        if cmd.query:
            ax, _ = self._axis_arg(cmd)
            return ax.mode
        ax, (mode,) = self._axis_arg(cmd, 2)
        mode = mode.upper()
        if mode in ("POS", "POSITION"):
            new = "POS"
        elif mode == "OFF":
            new = "OFF"
        elif mode in ("SYNT", "SYNTHESIS"):
            if not self.synthesis:
                raise ScpiError(-221, "Settings conflict; this controller has no synthesis mode")
            new = "SYNT"
        elif mode == "RATE":
            raise ScpiError(-221, f"Settings conflict; {mode} mode is not modelled")
        else:
            raise ScpiError(-224, f"Illegal parameter value; mode {mode!r}")
        if new != ax.mode:
            self._no_function_running(ax)
        ax.mode = new
        return None

    def _no_function_running(self, ax: _Axis) -> None:
        running = self.world.motion_status().profile
        if running is not None and running.axis == ax.name:
            raise ScpiError(ERR_FUNCTION_RUNNING, "Synthesis function running; ABORt it first")

    def _drive_enabled(self, ax: _Axis) -> None:
        """The checks every motion command makes, in this order."""
        if self.safety_open:
            raise ScpiError(ERR_SAFETY_OPEN, "Safety interlock open")
        if ax.fault is not None:
            raise ScpiError(ERR_AXIS_FAULT, f"Axis fault; {ax.fault}")
        if not ax.interlock_closed:
            raise ScpiError(ERR_INTERLOCK_OPEN, "Axis interlock open; close it first")

    def _demand_position(self, session: _Session, cmd: ParsedCommand) -> str | None:
        if cmd.query:
            ax, _ = self._axis_arg(cmd)
            return f"{self.world.motion_status().targets[ax.name]:.6f}"
        ax, (value_text,) = self._axis_arg(cmd, 2)
        value = self._number(value_text)
        if not ax.low <= value <= ax.high:
            msg = f"Data out of range; {value:g} outside [{ax.low:g}, {ax.high:g}]"
            raise ScpiError(-222, msg)
        self._drive_enabled(ax)
        if ax.mode != "POS":
            raise ScpiError(ERR_NOT_POSITION_MODE, "Axis not in position mode")
        self.world.move_to({ax.name: value})
        self.aborted = False
        return None

    def _read_position(self, session: _Session, cmd: ParsedCommand) -> str:
        self._query_only(cmd)
        ax, _ = self._axis_arg(cmd)
        return f"{self.world.motion_status().positions[ax.name]:.6f}"

    def _interlock(self, session: _Session, cmd: ParsedCommand) -> str:
        self._query_only(cmd)
        ax, _ = self._axis_arg(cmd)
        return "1" if ax.interlock_closed else "0"

    def _interlock_close(self, session: _Session, cmd: ParsedCommand) -> None:
        self._no_query(cmd)
        ax, _ = self._axis_arg(cmd)
        if self.safety_open:
            raise ScpiError(ERR_SAFETY_OPEN, "Safety interlock open")
        if ax.fault is not None:
            raise ScpiError(ERR_AXIS_FAULT, f"Axis fault; {ax.fault}")
        ax.interlock_closed = True

    def _interlock_open(self, session: _Session, cmd: ParsedCommand) -> None:
        self._no_query(cmd)
        ax, _ = self._axis_arg(cmd)
        if ax.interlock_closed and self.world.motion_status().busy:
            self._abort_all()
        ax.interlock_closed = False

    def _abort(self, session: _Session, cmd: ParsedCommand) -> None:
        self._no_query(cmd)
        self._want_args(cmd, 0)
        self._abort_all()

    def _status(self, session: _Session, cmd: ParsedCommand) -> str:
        self._query_only(cmd)
        ax, _ = self._axis_arg(cmd)
        st = self.world.motion_status()
        tt = self.world.bench.turntable
        t = self.world.now_s()
        moving = tt.is_busy(t)
        bits = (
            (STATUS_INTERLOCK_CLOSED if ax.interlock_closed else 0)
            | (STATUS_IN_MOTION if moving else 0)
            | (STATUS_IN_POSITION if st.settled else 0)
            | (STATUS_FAULT if ax.fault is not None else 0)
            | (STATUS_SAFETY_OPEN if self.safety_open else 0)
            | (STATUS_ABORTED if self.aborted else 0)
        )
        return str(bits)

    def _fault(self, session: _Session, cmd: ParsedCommand) -> str:
        self._query_only(cmd)
        ax, _ = self._axis_arg(cmd)
        return '0,"No fault"' if ax.fault is None else f'1,"{ax.fault}"'

    def _fault_clear(self, session: _Session, cmd: ParsedCommand) -> None:
        self._no_query(cmd)
        ax, _ = self._axis_arg(cmd)
        ax.fault = None

    def _limit(self, cmd: ParsedCommand, attr: str) -> str | None:
        if cmd.query:
            ax, _ = self._axis_arg(cmd)
            return f"{getattr(ax, attr):.6f}"
        ax, (value_text,) = self._axis_arg(cmd, 2)
        value = self._number(value_text)
        spec = self.world.bench.turntable.axes[ax.name]
        if not spec.min_pos <= value <= spec.max_pos:
            raise ScpiError(
                -222,
                f"Data out of range; limit {value:g} beyond the hardware range "
                f"[{spec.min_pos:g}, {spec.max_pos:g}]",
            )
        new_low = value if attr == "low" else ax.low
        new_high = value if attr == "high" else ax.high
        if new_low >= new_high:
            raise ScpiError(-221, "Settings conflict; low limit must be below high limit")
        setattr(ax, attr, value)
        return None

    def _limit_low(self, session: _Session, cmd: ParsedCommand) -> str | None:
        return self._limit(cmd, "low")

    def _limit_high(self, session: _Session, cmd: ParsedCommand) -> str | None:
        return self._limit(cmd, "high")

    def _limit_velocity(self, session: _Session, cmd: ParsedCommand) -> str:
        self._query_only(cmd)
        ax, _ = self._axis_arg(cmd)
        return f"{self.world.bench.turntable.axes[ax.name].max_rate:.6f}"

    def _limit_acceleration(self, session: _Session, cmd: ParsedCommand) -> str:
        self._query_only(cmd)
        ax, _ = self._axis_arg(cmd)
        return f"{self.world.bench.turntable.axes[ax.name].max_accel:.6f}"

    def _unit(self, session: _Session, cmd: ParsedCommand) -> str:
        self._query_only(cmd)
        ax, _ = self._axis_arg(cmd)
        return "MM" if ax.name == "rail" else "DEG"

    def _simulate_safety(self, session: _Session, cmd: ParsedCommand) -> str | None:
        if cmd.query:
            self._want_args(cmd, 0)
            return "OPEN" if self.safety_open else "CLOS"
        (state,) = self._want_args(cmd, 1)
        if state.upper() not in ("OPEN", "CLOS", "CLOSE"):
            raise ScpiError(-224, f"Illegal parameter value; {state!r} (OPEN or CLOSe)")
        self.set_safety_open(state.upper() == "OPEN")
        return None

    def _simulate_fault(self, session: _Session, cmd: ParsedCommand) -> None:
        self._no_query(cmd)
        ax_text, text = self._want_args(cmd, 2)
        self._axis_of(ax_text)  # names a bad axis before anything changes
        self.inject_fault(int(ax_text), text.strip('"') or "injected fault")

    # -- synthesis mode -----------------------------------------------------------------
    def _rotary_axis_arg(self, cmd: ParsedCommand, n_args: int) -> tuple[_Axis, tuple[str, ...]]:
        ax, rest = self._axis_arg(cmd, n_args)
        if ax.name == "rail":
            raise ScpiError(-221, "Settings conflict; synthesis runs on the rotary axes 1-3")
        return ax, rest

    def _synthesis(self, session: _Session, cmd: ParsedCommand) -> str:
        """The loaded function: ``NONE``, ``SINE,amplitude,frequency,cycles`` or
        ``RAMP,rate,acceleration,hold``."""
        self._query_only(cmd)
        ax, _ = self._axis_arg(cmd)
        f = ax.function
        if isinstance(f, SineProfile):
            return f"SINE,{f.amplitude_deg:.6f},{1.0 / f.period_s:.12g},{f.cycles}"
        if isinstance(f, RampProfile):
            return f"RAMP,{f.rate_deg_s:.6f},{f.accel_deg_s2:.6f},{f.hold_s:.6f}"
        return "NONE"

    def _load(self, ax: _Axis, make) -> None:
        self._no_function_running(ax)
        try:
            ax.function = make()
        except ValueError as exc:
            raise ScpiError(-222, f"Data out of range; {exc}") from None

    def _synthesis_sine(self, session: _Session, cmd: ParsedCommand) -> None:
        self._no_query(cmd)
        ax, (amp, freq, cycles) = self._rotary_axis_arg(cmd, 4)
        amplitude, frequency, n = self._number(amp), self._number(freq), self._number(cycles)
        if not n.is_integer():
            raise ScpiError(-104, f"Data type error; cycles must be a whole number, got {cycles!r}")
        if frequency <= 0:
            raise ScpiError(-222, f"Data out of range; frequency {frequency:g} Hz must be > 0")
        self._load(ax, lambda: SineProfile(amplitude, 1.0 / frequency, int(n)))

    def _synthesis_ramp(self, session: _Session, cmd: ParsedCommand) -> None:
        self._no_query(cmd)
        ax, args = self._rotary_axis_arg(cmd, 4)
        rate, accel, hold = (self._number(a) for a in args)
        self._load(ax, lambda: RampProfile(rate, hold, accel))

    def _synthesis_start(self, session: _Session, cmd: ParsedCommand) -> None:
        """Run the loaded function about the axis' position now, if it keeps within the
        soft limits and the axis' rate and acceleration limits (-222 naming each)."""
        self._no_query(cmd)
        ax, _ = self._rotary_axis_arg(cmd, 1)
        self._drive_enabled(ax)
        if ax.mode != "SYNT":
            raise ScpiError(ERR_NOT_SYNTHESIS_MODE, "Axis not in synthesis mode")
        if ax.function is None:
            raise ScpiError(ERR_NO_FUNCTION, "No synthesis function loaded")
        spec = self.world.bench.turntable.axes[ax.name]
        here = self.world.motion_status().positions[ax.name]
        problems = ax.function.started_at(here).limit_problems(
            ax.name, ax.low, ax.high, spec.max_rate, spec.max_accel
        )
        if problems:
            raise ScpiError(-222, "Data out of range; " + "; ".join(p.message for p in problems))
        try:
            self.world.run_profile(ax.name, ax.function)
        except AxisBusyError as exc:
            raise ScpiError(-221, f"Settings conflict; {exc}") from None
        except SoftLimitError as exc:
            raise ScpiError(-222, f"Data out of range; {exc}") from None
        self.aborted = False

    def _synthesis_status(self, session: _Session, cmd: ParsedCommand) -> str:
        """``IDLE``, or the running function's kind, elapsed and remaining seconds."""
        self._query_only(cmd)
        ax, _ = self._axis_arg(cmd)
        running = self.world.motion_status().profile
        if running is None or running.axis != ax.name:
            return "IDLE"
        return f"{running.kind.upper()},{running.elapsed_s:.6f},{running.remaining_s:.6f}"


TREE_BY_PATH = {tuple(n.upper() for n in path): name for path, name in TREE.items()}


class _Handler(TrackedHandler, socketserver.StreamRequestHandler):
    server: _Server

    def handle(self) -> None:
        session = _Session()
        controller = self.server.controller
        while True:
            try:
                raw = self.rfile.readline(MAX_LINE_BYTES + 1)
            except OSError:
                return
            if not raw:
                return
            if len(raw) > MAX_LINE_BYTES and not raw.endswith(b"\n"):
                session.push(ScpiError(-363, "Input buffer overrun"))
                while raw and not raw.endswith(b"\n"):  # skip the rest of that line
                    raw = self.rfile.readline(MAX_LINE_BYTES + 1)
                continue
            try:
                line = raw.decode("ascii").rstrip("\r\n")
            except UnicodeDecodeError:
                session.push(ScpiError(-101, "Invalid character; non-ASCII byte"))
                continue
            reply = controller.execute(session, line)
            if reply is not None:
                try:
                    self.wfile.write(reply.encode("ascii") + b"\n")
                except OSError:
                    return


class _Server(TrackedTCPServer):
    def __init__(self, address: tuple[str, int], controller: RateTableController) -> None:
        self.controller = controller
        super().__init__(address, _Handler)


class RateTableEmulator(ServedEmulator):
    """The controller on a TCP port: ``start()`` serves in a thread, ``close()`` stops and
    drops every client connection (a link drop, as far as clients can tell)."""

    thread_name = "rate-table-emulator"

    def __init__(
        self,
        world: SimWorld,
        host: str = "127.0.0.1",
        port: int = 5025,
        *,
        synthesis: bool = True,
    ) -> None:
        self.controller = RateTableController(world, synthesis=synthesis)
        self._server = _Server((host, port), self.controller)

    @property
    def resource(self) -> str:
        """The VISA resource name of this emulator."""
        host, port = self.address
        return f"TCPIP::{host}::{port}::SOCKET"
