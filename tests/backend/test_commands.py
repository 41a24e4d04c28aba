"""The server's subcommands as the entry-point group registers them
(``backend/commands.py``): the same objects, options as documented, and ``tofpose
openapi`` writing the server's document through one."""

from __future__ import annotations

import argparse
import json

import pytest

from backend import commands
from tofpose.cli import build_parser, registered_commands


def test_the_registered_commands_are_the_servers():
    registered = registered_commands()
    for c in (commands.SERVE, commands.REPORT, commands.KEYS, commands.RECORD):
        assert registered[c.name] is c
    assert registered["emulate"] is commands.EMULATE
    assert registered["openapi"] is commands.OPENAPI


def test_report_needs_a_database_and_an_output():
    parser = build_parser({"report": commands.REPORT})
    with pytest.raises(SystemExit) as exc:
        parser.parse_args(["report", "3"])
    assert exc.value.code == 2
    args = parser.parse_args(["report", "3", "--db", "sqlite:///x.db", "--out", "r.html"])
    assert (args.campaign_id, args.format, args.reference, args.calibration) == (
        3,
        "html",
        "lab",
        None,
    )


def test_keys_create_takes_a_scope():
    sub = argparse.ArgumentParser().add_subparsers(dest="cmd")
    commands.KEYS.add_parser(sub)
    parser = sub.choices["keys"]
    args = parser.parse_args(["create", "ci", "--scope", "operate"])
    assert (args.action, args.name, args.scope) == ("create", "ci", "operate")


def test_openapi_writes_the_servers_document(tmp_path):
    out = tmp_path / "openapi.json"
    assert commands.OPENAPI.run({"out": str(out)}) == 0
    doc = json.loads(out.read_text())
    assert doc["openapi"].startswith("3.") and "/api/health" in doc["paths"]
