"""Argument helpers shared by subcommands."""

from __future__ import annotations

import argparse
import math
from pathlib import Path

from ..io import read_vehicle, record_run_info
from ..params import CameraParams, ParameterError, VehicleParams


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


NOISE_KINDS = ("none", "paper", "uniform", "gaussian")


def add_noise_arguments(parser: argparse.ArgumentParser, default: str | None, extra_kinds: tuple[str, ...] = (),
                        extra_help: str = "") -> None:  # fmt: skip
    """The camera-noise grammar every command shares: ``--noise KIND --e1-noise M --e2-noise RAD``."""
    parser.add_argument(
        "--noise", choices=[*extra_kinds, *NOISE_KINDS], default=default,
        help="camera noise on e1, e2: none; paper = uniform, HALF-WIDTH 1 cm and 1 deg (STANDARD DEVIATION "
        "0.577 cm, 0.577 deg; --e1-noise/--e2-noise are ignored); uniform = +/-HALF-WIDTH given by "
        "--e1-noise/--e2-noise; gaussian = STANDARD DEVIATION given by --e1-noise/--e2-noise" + extra_help,
    )  # fmt: skip
    parser.add_argument("--e1-noise", type=non_negative_float, default=0.01,
                        help="e1 noise [m]: the HALF-WIDTH for --noise uniform, the STANDARD DEVIATION for --noise gaussian")
    parser.add_argument("--e2-noise", type=non_negative_float, default=math.radians(0.1),
                        help="e2 noise [rad]: the HALF-WIDTH for --noise uniform, the STANDARD DEVIATION for --noise "
                        "gaussian (default 0.1 deg = 0.001745 rad)")  # fmt: skip


def camera_from_noise_args(args: argparse.Namespace, rate: float, **camera_kwargs) -> CameraParams:
    """The camera of ``--noise``/``--e1-noise``/``--e2-noise`` at ``rate`` [Hz]."""
    if args.noise == "paper":
        return CameraParams.paper_noise(rate=rate, **camera_kwargs)
    if args.noise in (None, "none"):
        return CameraParams(rate=rate, **camera_kwargs)
    if args.noise in ("uniform", "gaussian"):
        return CameraParams(rate=rate, noise=args.noise, e1_noise=args.e1_noise, e2_noise=args.e2_noise, **camera_kwargs)
    raise ParameterError(f"--noise {args.noise!r} does not describe a camera")
