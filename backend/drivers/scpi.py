"""Motion driver for an SCPI rate-table controller (ACUTROL3000-style command set) through
PyVISA (``pyvisa`` with the pure-Python ``pyvisa-py`` backend; install ``tofpose[scpi]``).

The resource is any VISA resource name; for a controller on the network that is
``TCPIP::host::port::SOCKET``, and GPIB or serial controllers work the same way. The
command set (docs/devices.md, "Rate-table protocol"): ``:MODE n,POS``,
``:INTerlock:CLOSe n``, ``:DEMand:POSition n,deg``, ``:READ:POSition? n``, ``:STATus? n``,
``:ABORt``, limits with ``:LIMit:POSition:LOW? n`` / ``HIGH?`` / ``:LIMit:VELocity? n`` /
``:LIMit:ACCeleration? n``, errors from ``:SYSTem:ERRor?``; motion profiles through
synthesis mode: ``:MODE n,SYNT``, ``:SYNThesis:SINE`` / ``:SYNThesis:RAMP``,
``:SYNThesis:STARt n``, ``:SYNThesis:STATus? n``.

Policy:

- Every command that changes state is followed by ``:SYSTem:ERRor?``; a non-zero answer
  raises ``MotionError`` naming the command and the controller's message.
- Before a move, the driver puts each axis it moves in position mode and closes its
  interlock (as an operator's software does); a fault or an open safety interlock is
  reported, never overridden. A profile does the same with synthesis mode.
- A controller without synthesis mode (its ``:SYNThesis:STATus?`` query is an undefined
  header at connect time) runs no profiles: ``profile_unavailable`` says so, and
  ``run_profile`` raises ``MotionError`` with that sentence.
- ``stop`` goes out on a session of its own, opened at connect time, so it never waits
  behind a query in flight on the command session.
- Any I/O error or time-out closes the session; the next call reconnects (the server
  meanwhile shows the motion system degraded).
"""

from __future__ import annotations

import contextlib
import re
import threading
import time
from typing import Any

from backend.drivers.base import AxisLimits, MotionError, MotionStatus, ProfileStatus
from tofpose.lab.motion_profile import MotionProfile, SineProfile

DEFAULT_AXIS_NUMBERS = {"yaw": 1, "pitch": 2, "roll": 3, "rail": 4}
STATUS_IN_MOTION = 2
STATUS_IN_POSITION = 4
STATUS_ABORTED = 32
_ERROR_AT_END = re.compile(r'(?:^|;)(?P<code>[+-]?\d+),"(?P<message>[^"]*)"$')


def _visa() -> Any:
    try:
        import pyvisa
    except ImportError as exc:  # pragma: no cover - the extra is part of dev installs
        raise MotionError(
            "the scpi motion driver needs PyVISA: pip install 'tofpose[scpi]'"
        ) from exc
    return pyvisa


class ScpiRateTable:
    """A rate table behind an SCPI controller (implements ``MotionDriver``).

    resource : VISA resource name, e.g. ``TCPIP::127.0.0.1::5025::SOCKET``.
    axis_numbers : {axis name: controller axis number}; axes the controller does not
        have (its limit query fails) are left out.
    timeout_s : I/O time-out of each command.
    """

    name = "scpi"

    def __init__(
        self,
        resource: str,
        *,
        axis_numbers: dict[str, int] | None = None,
        timeout_s: float = 2.0,
        visa_library: str = "@py",
    ) -> None:
        self.resource = resource
        self.timeout_s = timeout_s
        self._rm = _visa().ResourceManager(visa_library)
        self._lock = threading.Lock()
        self._stop_lock = threading.Lock()
        self._session: Any = None
        self._stop_session: Any = None
        self.identity = ""
        self._connect()
        self.axis_numbers, self.axes = self._read_axes(axis_numbers or DEFAULT_AXIS_NUMBERS)
        if not self.axes:
            raise MotionError(f"{resource}: the controller reports none of the axes asked for")
        self.profile_unavailable = self._probe_synthesis()

    # -- link ---------------------------------------------------------------------------
    def _open(self) -> Any:
        pyvisa = _visa()
        try:
            inst = self._rm.open_resource(
                self.resource,
                read_termination="\n",
                write_termination="\n",
                timeout=int(self.timeout_s * 1000),
            )
        except (pyvisa.errors.VisaIOError, OSError, ValueError) as exc:
            raise MotionError(f"cannot open {self.resource}: {exc}") from exc
        return inst

    def _connect(self) -> None:
        self._session = self._open()
        self._stop_session = self._open()
        try:
            self.identity = self._query_raw(self._session, "*CLS;*IDN?")
        except MotionError as exc:
            raise MotionError(
                f"cannot reach the rate-table controller at {self.resource}: {exc.__cause__}"
            ) from exc

    def _drop(self) -> None:
        for inst in (self._session, self._stop_session):
            if inst is not None:
                # closing a dead link may fail; it is gone either way
                with contextlib.suppress(Exception):
                    inst.close()
        self._session = self._stop_session = None

    def _ensure(self) -> Any:
        if self._session is None:
            self._drop()
            self._connect()
        return self._session

    def _query_raw(self, inst: Any, text: str) -> str:
        pyvisa = _visa()
        try:
            return str(inst.query(text)).strip()
        except (pyvisa.errors.VisaIOError, OSError, ConnectionError) as exc:
            self._drop()
            raise MotionError(f"{self.resource}: no answer to {text!r}: {exc}") from exc

    def _exchange(self, inst: Any, text: str) -> list[str]:
        """Send ``text`` with an error-queue query in the same message; return the answers
        of its queries, or raise ``MotionError`` with the controller's error."""
        reply = self._query_raw(inst, f"{text};:SYST:ERR?")
        m = _ERROR_AT_END.search(reply)
        if m is None:
            raise MotionError(f"{self.resource}: unreadable reply {reply!r} to {text!r}")
        if int(m["code"]) != 0:
            self._query_raw(inst, "*CLS;*OPC?")  # one error is enough to report
            raise MotionError(f"the controller refused {text!r}: {m['code']} {m['message']}")
        head = reply[: m.start()]
        return head.split(";") if head else []

    def query(self, text: str) -> list[str]:
        """Queries (``;``-joined) on the command session, reconnecting first if the link
        was lost; returns their answers."""
        with self._lock:
            return self._exchange(self._ensure(), text)

    def command(self, text: str) -> None:
        """State-changing commands, checked against the controller's error queue."""
        self.query(text)

    # -- axes ---------------------------------------------------------------------------
    def _read_axes(self, wanted: dict[str, int]) -> tuple[dict[str, int], dict[str, AxisLimits]]:
        numbers, axes = {}, {}
        for name, n in wanted.items():
            try:
                low, high, vel, unit = self.query(
                    f":LIM:POS:LOW? {n};:LIM:POS:HIGH? {n};:LIM:VEL? {n};:UNIT? {n}"
                )
            except MotionError:  # the controller has no such axis
                if self._session is None:
                    raise
                continue
            numbers[name] = n
            accel = self._optional_number(f":LIM:ACC? {n}")
            axes[name] = AxisLimits(
                name, unit.strip().lower(), float(low), float(high), float(vel), accel
            )
        return numbers, axes

    def _optional_number(self, query: str) -> float | None:
        """The answer to a query some controllers lack, or None when this one does."""
        try:
            (answer,) = self.query(query)
        except MotionError:
            if self._session is None:  # the link, not the command: report it
                raise
            return None
        return float(answer)

    def _probe_synthesis(self) -> str | None:
        """None if the controller has synthesis mode, else why profiles cannot run."""
        n = next(iter(self.axis_numbers.values()))
        try:
            self.query(f":SYNT:STAT? {n}")
        except MotionError as exc:
            if self._session is None:
                raise
            return (
                f"the controller at {self.resource} has no synthesis mode ({exc}), so it "
                "cannot run motion profiles"
            )
        return None

    def _prepare(self, inst: Any, n: int, mode: str) -> None:
        """Close axis ``n``'s interlock and select ``mode`` (``POS``, ``SYNT``) if needed."""
        current, closed = self._exchange(inst, f":MODE? {n};:INT? {n}")
        if closed.strip() != "1":
            self._exchange(inst, f":INT:CLOS {n}")
        if current.strip().upper() != mode:
            self._exchange(inst, f":MODE {n},{mode}")

    # -- MotionDriver -------------------------------------------------------------------
    def move_to(self, setpoints: dict[str, float]) -> None:
        with self._lock:
            inst = self._ensure()
            for name in setpoints:
                self._prepare(inst, self.axis_numbers[name], "POS")
            for name, value in setpoints.items():
                self._exchange(inst, f":DEM:POS {self.axis_numbers[name]},{value:.6f}")

    def run_profile(self, axis: str, profile: MotionProfile) -> None:
        """Load ``profile`` into the controller's synthesis generator for ``axis`` and
        start it there (the controller times it and checks it against its own limits);
        ``MotionError`` when the controller has no synthesis mode or refuses."""
        if self.profile_unavailable is not None:
            raise MotionError(self.profile_unavailable)
        n = self.axis_numbers[axis]
        if isinstance(profile, SineProfile):
            load = (
                f":SYNT:SINE {n},{profile.amplitude_deg:.6f},{1.0 / profile.period_s:.12g},"
                f"{profile.cycles}"
            )
        else:
            load = (
                f":SYNT:RAMP {n},{profile.rate_deg_s:.6f},{profile.accel_deg_s2:.6f},"
                f"{profile.hold_s:.6f}"
            )
        with self._lock:
            inst = self._ensure()
            self._prepare(inst, n, "SYNT")
            self._exchange(inst, load)
            self._exchange(inst, f":SYNT:STAR {n}")

    def stop(self) -> None:
        """Abort every axis, on the stop session (never queued behind another command)."""
        with self._stop_lock:
            inst = self._stop_session
            if inst is None:
                with self._lock:
                    self._drop()
                    self._connect()
                inst = self._stop_session
            self._exchange(inst, ":ABOR")

    def status(self) -> MotionStatus:
        """Encoders, demands and state bits of every axis in one round trip (plus each
        rotary axis' synthesis state when the controller has one), stamped with the
        host's monotonic clock halfway through it."""
        per_axis = ":READ:POS? {n};:DEM:POS? {n};:STAT? {n}"
        if self.profile_unavailable is None:
            per_axis += ";:SYNT:STAT? {n}"
        k = per_axis.count(";") + 1
        query = ";".join(per_axis.format(n=n) for n in self.axis_numbers.values())
        sent_s = time.monotonic()
        parts = self.query(query)
        time_s = 0.5 * (sent_s + time.monotonic())
        if len(parts) != k * len(self.axis_numbers):
            raise MotionError(f"{self.resource}: status reply has {len(parts)} fields")
        positions, targets, busy, settled, stopped = {}, {}, False, True, False
        profile = None
        for i, name in enumerate(self.axis_numbers):
            pos, target, bits, *synthesis = parts[k * i : k * i + k]
            positions[name], targets[name] = float(pos), float(target)
            b = int(bits)
            busy |= bool(b & STATUS_IN_MOTION)
            settled &= bool(b & STATUS_IN_POSITION)
            stopped |= bool(b & STATUS_ABORTED)
            if synthesis and synthesis[0].strip().upper() != "IDLE":
                kind, elapsed, remaining = synthesis[0].split(",")
                profile = ProfileStatus(
                    name, kind.strip().lower(), float(elapsed), float(elapsed) + float(remaining)
                )
        return MotionStatus(
            positions, targets, busy, settled and not busy, stopped, time_s, profile
        )

    def reset_faults(self) -> None:
        """Clear the controller's axis faults (the operator's acknowledgement after the
        cause is fixed); interlocks stay open until the next move closes them."""
        self.command(";".join(f":FAUL:CLE {n}" for n in self.axis_numbers.values()))

    def describe(self) -> dict[str, str]:
        """Model, firmware and link state for GET /api/devices."""
        parts = [p.strip() for p in self.identity.split(",")] + ["", "", "", ""]
        return {
            "model": f"{parts[0]} {parts[1]}".strip(),
            "firmware": parts[3],
            "link": "up" if self._session is not None else "down",
            "address": self.resource,
        }

    def close(self) -> None:
        with self._lock:
            self._drop()
        with contextlib.suppress(Exception):  # it may already be gone at shutdown
            self._rm.close()
