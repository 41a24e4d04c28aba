"""SCPI message parsing for the rate-table emulator (IEEE 488.2 / SCPI-1999 subset).

A program message is one line (``\\n``-terminated, a trailing ``\\r`` is ignored) of
commands separated by ``;``. Each command is a header (``:MODE``, ``:DEMand:POSition?``,
``*IDN?``) and optional comma-separated parameters after white space. Header nodes match
case-insensitively in their short form (the upper-case letters of the long form) or
their long form, as SCPI defines; a leading ``:`` is optional.
"""

from __future__ import annotations

from dataclasses import dataclass


class ScpiError(Exception):
    """An SCPI error: ``code`` (negative: SCPI standard; positive: device specific)."""

    def __init__(self, code: int, message: str) -> None:
        super().__init__(f'{code},"{message}"')
        self.code = code
        self.message = message


@dataclass(frozen=True)
class ParsedCommand:
    """One command of a program message: ``path`` as canonical long-form nodes
    (e.g. ``("DEMAND", "POSITION")``), ``query`` for a trailing ``?``, ``args`` as the raw
    parameter strings, ``common`` for ``*XXX`` commands."""

    path: tuple[str, ...]
    query: bool
    args: tuple[str, ...]
    common: bool = False


def short_form(long_form: str) -> str:
    """``"DEMand"`` -> ``"DEM"``: the upper-case letters of an SCPI mnemonic."""
    return "".join(c for c in long_form if c.isupper() or c.isdigit())


def match_node(token: str, long_form: str) -> bool:
    """True if ``token`` is ``long_form``'s short or long form (case-insensitive)."""
    t = token.upper()
    return t == long_form.upper() or t == short_form(long_form).upper()


def split_message(line: str) -> list[str]:
    """The commands of one program message (``;``-separated; quotes respected)."""
    out: list[str] = []
    cur: list[str] = []
    quoted = False
    for ch in line.strip():
        if ch == '"':
            quoted = not quoted
        if ch == ";" and not quoted:
            out.append("".join(cur).strip())
            cur = []
        else:
            cur.append(ch)
    out.append("".join(cur).strip())
    return [c for c in out if c]


def parse_command(text: str, tree: dict[tuple[str, ...], str]) -> ParsedCommand:
    """Parse one command against ``tree`` ({long-form node path: handler name}).

    Raises ``ScpiError(-113)`` for a header the tree does not hold.
    """
    head, _, rest = text.partition(" ")
    head = head.strip()
    args = tuple(a.strip() for a in rest.split(",")) if rest.strip() else ()
    query = head.endswith("?")
    head = head.rstrip("?")
    if head.startswith("*"):
        return ParsedCommand((head.upper(),), query, args, common=True)
    tokens = [t for t in head.lstrip(":").split(":")]
    if not tokens or any(not t for t in tokens):
        raise ScpiError(-102, f"Syntax error; header {text.split(' ')[0]!r}")
    for path in tree:
        if len(path) == len(tokens) and all(
            match_node(t, n) for t, n in zip(tokens, path, strict=True)
        ):
            return ParsedCommand(tuple(n.upper() for n in path), query, args)
    raise ScpiError(-113, f"Undefined header; {head!r}")
