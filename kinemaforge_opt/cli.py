"""The ``kinemaforge`` command.

Each subcommand lives in ``kinemaforge_opt/commands/<name>.py`` and exposes
``register(subparsers)``, which adds its parser and sets ``func(args) -> int``.
Exit status: 0 done; 2 bad input (one message on stderr naming the file, field or joint);
1 anything else.
"""

from __future__ import annotations

import argparse
import importlib
import pkgutil
import sys

from . import __version__, commands
from .errors import KinemaforgeError

EPILOG = """\
examples:
  kinemaforge demo -o out/demo                       the main job on embedded default data
  kinemaforge calibrate models/laptop/laptop.urdf rec.csv -o out/cal
  kinemaforge diagnose models/laptop/laptop.urdf rec.csv -o out/diag
  kinemaforge synth --list                           the benchmark catalogue

Run `kinemaforge COMMAND --help` for each command's options.
"""


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="kinemaforge",
        description="Turn recordings of articulated objects into simulation-ready URDFs whose "
        "physics matches the recording; calibrate and diagnose joint dynamics.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--version", action="version", version=f"kinemaforge {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for info in sorted(pkgutil.iter_modules(commands.__path__), key=lambda m: m.name):
        importlib.import_module(f"{commands.__name__}.{info.name}").register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    try:
        return int(args.func(args) or 0)
    except KinemaforgeError as e:
        print(f"kinemaforge {args.command}: error: {e}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
