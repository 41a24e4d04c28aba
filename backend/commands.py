"""The server's ``tofpose`` subcommands: ``serve``, ``report``, ``keys``, ``record``,
``emulate`` and ``openapi``, registered in the entry-point group ``tofpose.commands``
(pyproject.toml) so that the library's command line (``tofpose.cli``) offers them
without importing the server. Each is a ``ServerCommand``: its parser here, its work
imported only when it runs."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any


@dataclass(frozen=True)
class ServerCommand:
    """One subcommand: ``add_parser(subparsers)`` adds its options, ``run(options)``
    does it (``options``: the parsed arguments without ``cmd``) and returns the exit
    code."""

    name: str
    add_parser: Callable[[Any], None]
    work: Callable[[dict[str, Any]], int]

    def run(self, options: dict[str, Any]) -> int:
        return self.work(options)


def _serve_parser(sub: Any) -> None:
    p = sub.add_parser(
        "serve", help="run the server (simulated devices by default); settings also from TOFPOSE_*"
    )
    p.add_argument("--host", help="bind address (default 127.0.0.1)")
    p.add_argument("--port", type=int, help="port (default 8000)")
    p.add_argument("--db", dest="database_url", help="SQLAlchemy URL (default SQLite in data dir)")
    p.add_argument("--data-dir", help="data directory (default ./data)")
    p.add_argument("--camera", help="'sim', 'replay:REC.h5' or 'tofcam660:ADDRESS'")
    p.add_argument("--motion", help="'sim', 'none' or 'scpi:HOST:PORT'")
    p.add_argument("--rate", dest="replay_rate_hz", type=float, help="replay rate, Hz")
    p.add_argument("--viser-port", type=int, help="port of the 3-D scene (default 8080, 0 = any)")
    p.add_argument(
        "--no-viser",
        dest="viser",
        action="store_false",
        default=None,
        help="do not run the 3-D scene",
    )
    p.add_argument(
        "--foxglove-port",
        type=int,
        help="publish the live stream to Foxglove on this port (default off; "
        "0 = any free port; docs/interop.md)",
    )


def _report_parser(sub: Any) -> None:
    p = sub.add_parser("report", help="write a campaign's accuracy report from the database")
    p.add_argument("campaign_id", type=int)
    p.add_argument("--db", required=True, help="SQLAlchemy URL, e.g. sqlite:///data/tofpose.db")
    p.add_argument("--format", choices=("html", "pdf", "csv", "json"), default="html")
    p.add_argument(
        "--reference",
        choices=("lab", "truth", "exact"),
        default="lab",
        help="lab: the lab's reference (encoders + nominal geometry); truth: the pose the "
        "simulator rendered (exact: its older name)",
    )
    p.add_argument(
        "--calibration",
        type=int,
        metavar="ID",
        help="reference = encoders + this stored bench calibration (as the API's ?calibration=ID)",
    )
    p.add_argument("--out", required=True, help="output file")


def _keys_parser(sub: Any) -> None:
    p = sub.add_parser("keys", help="API keys of the server's database: create, list, revoke")
    p.add_argument("--data-dir", help="data directory (default ./data)")
    p.add_argument("--db", dest="database_url", help="SQLAlchemy URL (default SQLite in data dir)")
    keys = p.add_subparsers(dest="action", required=True)
    q = keys.add_parser("create", help="make a key and print it (once: only its hash is kept)")
    q.add_argument("name")
    q.add_argument(
        "--scope",
        required=True,
        choices=("read", "operate", "admin"),
        help="read: live data and reports; operate: also every state change; "
        "admin: also keys, the audit trail and deletions",
    )
    keys.add_parser("list", help="every key: name, scope, created, revoked")
    q = keys.add_parser("revoke", help="revoke a key (a running server follows within 5 s)")
    q.add_argument("name")


def _record_parser(sub: Any) -> None:
    p = sub.add_parser(
        "record",
        help="record a running server's live stream to HDF5 (POST /api/recordings; docs/server.md)",
    )
    p.add_argument("--duration", type=float, required=True, help="seconds to record")
    p.add_argument("--name", help="what it is for (default: 'tofpose record' and the UTC time)")
    p.add_argument("--url", default="http://127.0.0.1:8000", help="the server")
    p.add_argument(
        "--key",
        help="API key of scope operate or admin (default: $TOFPOSE_API_KEY, else the key file)",
    )
    p.add_argument("--key-file", default="data/api_token", help="default data/api_token")
    p.add_argument("--out", help="the HDF5 file to write (default: NAME-ID.h5 here)")
    p.add_argument(
        "--no-download",
        dest="download",
        action="store_false",
        help="leave the recording on the server and print its URL",
    )


def _emulate_parser(sub: Any) -> None:
    p = sub.add_parser("emulate", help="run device emulators over a simulated lab")
    emu = p.add_subparsers(dest="device", required=True)
    for name, text in (
        ("camera", "ESPROS TOFcam-660 protocol (TCP 50660, UDP images to port 45454)"),
        ("table", "SCPI rate-table controller (ACUTROL3000-style)"),
        ("lab", "both, over one simulated lab (moving the table changes what the camera sees)"),
    ):
        q = emu.add_parser(name, help=text)
        if name == "camera":
            q.add_argument("--address", default="127.0.0.2", help="loopback address of its own")
        if name == "lab":
            q.add_argument("--camera-address", default="127.0.0.2")
            q.add_argument("--table-port", type=int, default=5025)
        if name != "camera":
            q.add_argument("--host", default="127.0.0.1", help="rate-table bind address")
        if name == "table":
            q.add_argument("--port", type=int, default=5025)
        q.add_argument("--target-distance-mm", type=float, default=15000.0)
        q.add_argument("--start-rail-mm", type=float, default=13000.0)
        q.add_argument("--seed", type=int, default=0)


def _openapi_parser(sub: Any) -> None:
    p = sub.add_parser("openapi", help="write the server's OpenAPI document (JSON)")
    p.add_argument("--out", required=True)


def _serve(options: dict[str, Any]) -> int:
    from backend import main

    return main.serve(options)


def _report(options: dict[str, Any]) -> int:
    from backend import main

    return main.report(options)


def _keys(options: dict[str, Any]) -> int:
    from backend import main

    return main.keys(options)  # backend/keys_cli.py


def _record(options: dict[str, Any]) -> int:
    from backend import main

    return main.record(options)  # backend/record_cli.py


def _emulate(options: dict[str, Any]) -> int:
    from backend.emulators import cli

    return cli.run(options)


def _openapi(options: dict[str, Any]) -> int:
    from backend import main

    return main.write_openapi(options["out"])


SERVE = ServerCommand("serve", _serve_parser, _serve)
REPORT = ServerCommand("report", _report_parser, _report)
KEYS = ServerCommand("keys", _keys_parser, _keys)
RECORD = ServerCommand("record", _record_parser, _record)
EMULATE = ServerCommand("emulate", _emulate_parser, _emulate)
OPENAPI = ServerCommand("openapi", _openapi_parser, _openapi)
