"""Command-line flags declared once, as tables: a table of ``Flag`` makes a command's parser
and the checks of the values given, so that a flag's name, help and check sit together."""

from __future__ import annotations

import argparse
import dataclasses
import re
from collections.abc import Callable, Iterable, Mapping
from typing import Any

#: A check of the parsed arguments: the error message, or None when they are good.
Check = Callable[[argparse.Namespace], str | None]


@dataclasses.dataclass(frozen=True)
class Flag:
    """One argument of a command: its names (a positional's name, or the option strings), its
    help, the other options of ``add_argument`` (type, metavar, action, default, ...) and a
    check of the value given (None: argparse's own checks are all)."""

    names: tuple[str, ...]
    help: str
    options: Mapping[str, Any] = dataclasses.field(default_factory=dict)
    check: Check | None = None

    def add_to(self, parser: argparse.ArgumentParser | argparse._ArgumentGroup) -> None:
        parser.add_argument(*self.names, help=self.help, **self.options)


def flag(*names: str, help: str, check: Check | None = None, **options: Any) -> Flag:
    """A ``Flag`` written as ``add_argument`` is called."""
    return Flag(names, help, options, check)


def switch(name: str, help: str) -> Flag:
    """A --NAME / --no-NAME flag, None when neither is given (the default applies)."""
    return flag(name, action=argparse.BooleanOptionalAction, default=None, help=help)


def add_flags(
    parser: argparse.ArgumentParser | argparse._ArgumentGroup, flags: Iterable[Flag]
) -> None:
    """Add ``flags`` to a parser (or a group of its arguments), in order."""
    for item in flags:
        item.add_to(parser)


def check_flags(args: argparse.Namespace, flags: Iterable[Flag]) -> None:
    """Run the checks of ``flags`` in order.

    Raises:
        ValueError: the message of the first check that fails.
    """
    for item in flags:
        message = None if item.check is None else item.check(args)
        if message is not None:
            raise ValueError(message)


def _auto_or_number(text: str) -> float | str:
    if text == "auto":
        return text
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected 'auto' or a number, got '{text}'") from None


def setting_flags(fields: Iterable[Mapping[str, Any]]) -> tuple[Flag, ...]:
    """A flag for each setting the command line takes (``_core.Settings.fields()``):
    --NAME-WITH-DASHES, its type from the setting's kind, its help the setting's own; a switch
    is --NAME / --no-NAME and says its default."""
    out = []
    for field in fields:
        if not field["command_line"]:
            continue
        name, text = "--" + field["name"].replace("_", "-"), str(field["help"])
        kind = field["kind"]
        if kind in ("switch", "auto_switch"):
            default = field["default"]
            shown = default if isinstance(default, str) else "on" if default else "off"
            out.append(switch(name, help=f"{text} (default: {shown})"))
        elif kind == "choice":
            out.append(flag(name, choices=re.findall(r'"(\w+)"', field["expected"]), help=text))
        else:
            kinds = {"number": float, "integer": int, "auto_number": _auto_or_number}
            out.append(flag(name, type=kinds[kind], help=text))
    return tuple(out)


# --- the contacts of a model file ---------------------------------------------------------------


def _floor_height(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected a height (m), or nothing (a plane under the model), got '{text}'"
        ) from None
    if value != value or value in (float("inf"), float("-inf")):
        raise argparse.ArgumentTypeError(f"expected a finite height (m), got '{text}'")
    return value


def _one_contacts_flag(args: argparse.Namespace) -> str | None:
    if args.no_contacts and args.contacts is not None:
        return f"--no-contacts and --contacts {args.contacts}: give one of them"
    if args.no_contacts and args.floor is not None:
        return "--floor needs contact points, and --no-contacts leaves them out: give one of them"
    return None


#: How a model file's collision shapes become contacts (``contact_options`` reads them).
CONTACT_FLAGS = (
    flag(
        "--contacts",
        choices=["collision", "none"],
        help="with a model file: its collision shapes as contact points (collision), or none. "
        "Default: an MJCF file's floors and the geoms MuJoCo collides with them are taken, as "
        "MuJoCo does; a URDF's collision shapes need --floor",
    ),
    flag(
        "--no-contacts",
        action="store_true",
        help="with a model file: no contacts (an MJCF file's floors and geoms left out); the "
        "same as --contacts none",
    ),
    flag(
        "--floor",
        nargs="?",
        const=True,
        type=_floor_height,
        metavar="Z",
        help="with a model file: a level floor (normal +z, friction 0.5) under the model's "
        "lowest collision point at its start pose, or at height Z (m), with the file's "
        "collision shapes as contacts (it replaces an MJCF file's own floors)",
        check=_one_contacts_flag,
    ),
)


def contact_options(args: argparse.Namespace) -> dict[str, Any]:
    """``load_scene``'s ``contacts`` and ``floor`` from the flags of ``CONTACT_FLAGS`` (checked
    first); none given: nothing, the scene's own."""
    check_flags(args, CONTACT_FLAGS)
    options: dict[str, Any] = {}
    if args.no_contacts or args.contacts is not None:
        options["contacts"] = "none" if args.no_contacts else args.contacts
    if args.floor is not None:
        options["floor"] = args.floor
    return options
