"""The ``hgrender`` command line.

Each sub-command lives in its own module under ``hgrender.cli`` and exposes ``register(subparsers)``,
which adds its parser and sets ``handler`` (a callable taking the parsed namespace and returning an exit
code). Modules are imported lazily by name so that, e.g., ``hgrender coherence`` never imports Mitsuba.
"""

from __future__ import annotations

import argparse
import importlib
import json
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from pydantic import ValidationError

from hgcore.artifacts.exr import ArtifactFormatError
from hgcore.errors import InputError

# Sub-command modules, in help order. A module missing here is simply not offered.
COMMAND_MODULES: tuple[str, ...] = (
    "hgrender.cli.render",
    "hgrender.cli.coherence",
    "hgrender.cli.service",
    "hgrender.cli.remote",
    "hgrender.cli.regress",
)


class CliError(Exception):
    """An error to report to the user as one line on stderr with exit code 2."""


def positive_int(text: str) -> int:
    """argparse type: an integer ≥ 1 (argparse names the option in its error)."""
    try:
        value = int(text)
    except ValueError:
        value = 0
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be a positive integer, got {text!r}")
    return value


def read_json_file(path: Path, field: str) -> Any:
    """The parsed JSON file; a ``CliError`` naming ``field``, the file and, for a syntax error, its
    line and column (``scene: bad.json:3:14: not valid JSON: Expecting ',' delimiter``)."""
    if not path.is_file():
        raise CliError(f"{field}: no such file {str(path)!r}")
    try:
        return json.loads(path.read_bytes())
    except json.JSONDecodeError as error:
        raise CliError(f"{field}: {path}:{error.lineno}:{error.colno}: not valid JSON: {error.msg}") from None
    except UnicodeDecodeError as error:
        raise CliError(f"{field}: {path}: not UTF-8 text (byte {error.start})") from None


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
    except (InputError, ValidationError, ArtifactFormatError) as error:
        # Bad input (it names the offending parameter, setting or file) is the user's to fix: one line,
        # exit 2. Anything else is a bug and ends with its traceback and exit 1.
        print(f"hgrender {args.command}: error: {error}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
