"""Argument helpers shared by subcommands."""

from __future__ import annotations

import argparse
import math
from pathlib import Path

from ..io import read_vehicle, record_run_info
from ..params import ParameterError, VehicleParams


DEFAULT_VEHICLE_SOURCE = "built-in default (the paper's D-class sedan)"


def add_vehicle_argument(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--vehicle",
        type=Path,
        default=None,
        help="vehicle JSON (keys m, Iz, lf, lr, Cf, Cr, ...); default: the paper's D-class sedan",
    )


def vehicle_from_args(args: argparse.Namespace) -> VehicleParams:
    """The vehicle of ``--vehicle`` (or the default sedan), recorded in the output manifest."""
    vehicle = read_vehicle(args.vehicle)
    source = str(args.vehicle) if args.vehicle is not None else DEFAULT_VEHICLE_SOURCE
    record_run_info("vehicle", {"source": source, "parameters": vehicle.to_dict()})
    return vehicle


def _number(text: str) -> float:
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None


def positive_float(text: str) -> float:
    """argparse type: a finite number > 0 (``-5``, ``0``, ``nan``, ``inf`` are refused)."""
    value = _number(text)
    if not (math.isfinite(value) and value > 0):
        raise argparse.ArgumentTypeError(f"must be a finite number > 0, got {text!r}")
    return value


def non_negative_float(text: str) -> float:
    """argparse type: a finite number >= 0."""
    value = _number(text)
    if not (math.isfinite(value) and value >= 0):
        raise argparse.ArgumentTypeError(f"must be a finite number >= 0, got {text!r}")
    return value


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
