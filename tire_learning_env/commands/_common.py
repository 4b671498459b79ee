"""Argument helpers shared by subcommands."""

from __future__ import annotations

import argparse
from pathlib import Path

from ..io import read_vehicle
from ..params import ParameterError, VehicleParams


def add_vehicle_argument(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--vehicle",
        type=Path,
        default=None,
        help="vehicle JSON (keys m, Iz, lf, lr, Cf, Cr, ...); default: the paper's D-class sedan",
    )


def vehicle_from_args(args: argparse.Namespace) -> VehicleParams:
    return read_vehicle(args.vehicle)


def parse_assignments(items: list[str] | None, what: str) -> dict[str, float]:
    """``["a=1", "b=2.5"]`` -> ``{"a": 1.0, "b": 2.5}``; a malformed item raises naming it."""
    out: dict[str, float] = {}
    for item in items or []:
        name, sep, value = item.partition("=")
        if not sep or not name:
            raise ParameterError(f"{what} must look like NAME=VALUE, got {item!r}")
        try:
            out[name.strip()] = float(value)
        except ValueError:
            raise ParameterError(f"{what} {name!r}: value {value!r} is not a number") from None
    return out
