"""``hgrender coherence``: the coherence a source gives a receiver (issue 2, item 7).

Thin wrapper over ``hgcore.optics.calculator.coherence_at`` (NumPy only: no Mitsuba, no Dr.Jit). Prints one
JSON object with ``--json``, else a readable table. Invalid values raise InputError naming the flag, which the
CLI entry point turns into exit code 2 and a one-line message.
"""

from __future__ import annotations

import argparse
import json
from typing import Any

from hgcore.errors import InputError
from hgcore.optics.calculator import coherence_at
from hgcore.optics.sources import SOURCE_KINDS

# calculator parameter → command-line flag, so that error messages name what the user typed.
_FLAG_FOR_PARAMETER = {
    "radius_m": "--radius",
    "length_m": "--length",
    "width_m": "--width",
    "height_m": "--height",
    "sigma_m": "--sigma",
    "distance_m": "--distance",
    "wavelength_nm": "--wavelength-nm",
    "axis": "--axis",
    "direction": "--direction",
    "modes": "--modes",
    "source": "--source",
}


def _vector(text: str) -> tuple[float, float, float]:
    """Parse ``X,Y,Z`` (argparse type; the calculator checks finiteness and length)."""
    parts = text.split(",")
    if len(parts) != 3:
        raise argparse.ArgumentTypeError(f"expected X,Y,Z, got {text!r}")
    try:
        return float(parts[0]), float(parts[1]), float(parts[2])
    except ValueError as error:
        raise argparse.ArgumentTypeError(f"expected three numbers X,Y,Z, got {text!r}") from error


def register(subparsers: Any) -> None:
    parser = subparsers.add_parser(
        "coherence",
        help="coherence (ℓ₁, ℓ₂, anisotropy, Θ, HG modes) a source gives a receiver",
        description=__doc__.splitlines()[0],
    )
    parser.add_argument("--source", required=True, choices=SOURCE_KINDS, help="emitter shape")
    parser.add_argument("--radius", type=float, metavar="M", help="radius (sphere, disk, cylinder), metres")
    parser.add_argument("--length", type=float, metavar="M", help="cylinder length, metres")
    parser.add_argument("--width", type=float, metavar="M", help="rectangle width, metres")
    parser.add_argument("--height", type=float, metavar="M", help="rectangle height, metres")
    parser.add_argument("--sigma", type=float, metavar="M", help="gaussian standard deviation, metres")
    parser.add_argument("--distance", type=float, required=True, metavar="M", help="source-receiver distance")
    parser.add_argument("--wavelength-nm", type=float, default=550.0, metavar="NM", help="default 550")
    parser.add_argument(
        "--axis",
        type=_vector,
        default=(1.0, 0.0, 0.0),
        metavar="X,Y,Z",
        help="cylinder axis; in-plane axis of a disk/rect (default 1,0,0)",
    )
    parser.add_argument(
        "--direction",
        type=_vector,
        default=(0.0, 0.0, 1.0),
        metavar="X,Y,Z",
        help="propagation direction from source to receiver (default 0,0,1)",
    )
    parser.add_argument("--modes", type=int, default=1, metavar="N", help="HG modes (1..64, default 1)")
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    parser.set_defaults(handler=run)


def _with_flag_name(error: InputError) -> InputError:
    """The calculator's error with its leading parameter name replaced by the command-line flag."""
    message = str(error)
    name, separator, rest = message.partition(":")
    flag = _FLAG_FOR_PARAMETER.get(name.split(" ")[0])
    if separator and flag is not None:
        return InputError(f"{flag}{name[len(name.split(' ')[0]) :]}:{rest}")
    return error


def _format_table(result: dict[str, Any]) -> str:
    def matrix(values: list[list[float]]) -> str:
        return f"[[{values[0][0]:.6g}, {values[0][1]:.6g}], [{values[1][0]:.6g}, {values[1][1]:.6g}]]"

    lines = [
        f"source        {result['source']} at r = {result['r_m']:g} m, λ = {result['wavelength_nm']:g} nm",
        f"l1            {result['l1_um']:.6g} µm",
        f"l2            {result['l2_um']:.6g} µm",
        f"anisotropy    {result['anisotropy']:.6g}",
        f"angle         {result['angle']:.6g} rad",
        f"area          {result['area_um2']:.6g} µm²",
        f"sigma (m²)    {matrix(result['sigma_m2'])}",
        f"theta (1/m²)  {matrix(result['theta'])}",
        f"M (1/m²)      {matrix(result['M'])}",
        f"frame x axis  {result['frame']['x_axis']}",
        f"frame y axis  {result['frame']['y_axis']}",
        "coefficients  " + ", ".join(f"c{c['n']}{c['m']}={c['value']:.6g}" for c in result["coefficients"]),
    ]
    return "\n".join(lines)


def run(args: argparse.Namespace) -> int:
    try:
        result = coherence_at(
            args.source,
            radius_m=args.radius,
            length_m=args.length,
            width_m=args.width,
            height_m=args.height,
            sigma_m=args.sigma,
            distance_m=args.distance,
            wavelength_nm=args.wavelength_nm,
            axis=args.axis,
            direction=args.direction,
            modes=args.modes,
        )
    except InputError as error:
        raise _with_flag_name(error) from None
    print(json.dumps(result) if args.json else _format_table(result))
    return 0
