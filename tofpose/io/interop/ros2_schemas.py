"""The complete ``ros2msg`` message definitions the ROS 2 MCAP export declares.

A channel's schema in a ROS 2 MCAP file is its type's ``.msg`` text followed by every type
it uses, recursively, each once and each after a line of 80 ``=`` and a line
``MSG: package/msg/Type`` (rosbag2's "Message Definition Encoding"). The ``.msg`` files
are ROS 2's own, shipped in ``ros2_msgs/`` (their NOTICE.md names the sources); nothing
here encodes a message: ``mcap-ros2-support``'s writer does that from these texts.
"""

from __future__ import annotations

import re
from functools import cache
from pathlib import Path

#: ROS 2's .msg files, as ``ros2_msgs/<package>/msg/<Type>.msg``
MSG_DIR = Path(__file__).with_name("ros2_msgs")

SEPARATOR = "=" * 80

#: the field types a .msg file can name that are not messages
PRIMITIVES = frozenset(
    ("bool", "byte", "char", "float32", "float64", "string", "wstring")
    + tuple(f"{s}int{n}" for s in ("", "u") for n in (8, 16, 32, 64))
)


def _split(type_name: str) -> tuple[str, str]:
    """``pkg/msg/Type`` -> (``pkg``, ``Type``); ValueError naming any other form."""
    parts = type_name.split("/")
    if len(parts) != 3 or parts[1] != "msg" or not all(parts):
        raise ValueError(f"ROS 2 message type {type_name!r} is not of the form package/msg/Type")
    return parts[0], parts[2]


def msg_text(type_name: str) -> str:
    """The ``.msg`` text of ``type_name`` (``pkg/msg/Type``) as ROS 2 ships it;
    ValueError naming the type when no definition ships for it."""
    package, name = _split(type_name)
    path = MSG_DIR / package / "msg" / f"{name}.msg"
    if not path.is_file():
        raise ValueError(f"no ROS 2 message definition ships for {type_name} (in {MSG_DIR})")
    return path.read_text()


def field_types(text: str, package: str) -> list[str]:
    """The message types (``pkg/msg/Type``) that the fields of a ``.msg`` ``text`` of
    ``package`` use, in order, repeats kept; constants and primitives left out. A bare
    ``Type`` is ``package``'s own, ``pkg/Type`` is ``pkg/msg/Type``."""
    out = []
    for line in text.splitlines():
        code = line.split("#", 1)[0].strip()
        if not code:
            continue
        base = re.sub(r"\[[^\]]*\]$", "", code.split()[0])  # float64[9], Type[], Type[<=3]
        base = re.sub(r"<=\d+$", "", base)  # string<=8
        if base in PRIMITIVES:
            continue
        if "/" not in base:
            out.append(f"{package}/msg/{base}")
        elif base.count("/") == 1:
            pkg, name = base.split("/")
            out.append(f"{pkg}/msg/{name}")
        else:
            out.append(base)
    return out


@cache
def definition(type_name: str) -> str:
    """The complete ``ros2msg`` definition of ``type_name`` (``pkg/msg/Type``): its own
    text, then each message type it depends on (depth-first, in the order fields name
    them, each once) after the two-line delimiter."""
    order: list[str] = []

    def visit(name: str) -> None:
        package, _ = _split(name)
        for dep in field_types(msg_text(name), package):
            if dep != type_name and dep not in order:
                order.append(dep)
                visit(dep)

    visit(type_name)
    parts = [msg_text(type_name).rstrip("\n")]
    parts += [f"{SEPARATOR}\nMSG: {dep}\n{msg_text(dep).rstrip(chr(10))}" for dep in order]
    return "\n".join(parts) + "\n"
