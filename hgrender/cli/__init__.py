"""The ``hgrender`` command line.

Each sub-command lives in its own module under ``hgrender.cli`` and exposes ``register(subparsers)``,
which adds its parser and sets ``handler`` (a callable taking the parsed namespace and returning an exit
code). Modules are imported lazily by name so that, e.g., ``hgrender coherence`` never imports Mitsuba.
"""

from __future__ import annotations

import argparse
import importlib
import sys
from collections.abc import Sequence

# Sub-command modules, in help order. A module missing here is simply not offered.
COMMAND_MODULES: tuple[str, ...] = (
    "hgrender.cli.render",
    "hgrender.cli.coherence",
    "hgrender.cli.service",
    "hgrender.cli.regress",
)


class CliError(Exception):
    """An error to report to the user as one line on stderr with exit code 2."""


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="hgrender", description=__doc__.splitlines()[0])
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for module_name in COMMAND_MODULES:
        try:
            module = importlib.import_module(module_name)
        except ModuleNotFoundError as error:
            if error.name == module_name:
                continue
            raise
        module.register(subparsers)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return int(args.handler(args) or 0)
    except CliError as error:
        print(f"hgrender {args.command}: error: {error}", file=sys.stderr)
        return 2
    except ValueError as error:
        # Domain validation errors (they name the offending parameter) are user errors, not crashes.
        print(f"hgrender {args.command}: error: {error}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
