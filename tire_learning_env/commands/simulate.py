"""``tire-learning simulate``: write a driving log from the truth vehicle."""

from __future__ import annotations

import argparse
from pathlib import Path

from ..dynamics import PlantEffects
from ..io import write_log
from ..params import ParameterError, TireParams
from ..roads import BUILTIN_ROADS
from ..scenarios import HIDDEN_EFFECTS, SCENARIO_ROADS, SPEED_PROFILES, parse_hidden_effects, speed_profile
from ..simulation import simulate
from ..tires import axle_tires
from ._common import (add_noise_arguments, add_vehicle_argument, camera_from_noise_args, parse_assignments, positive_float,
                      vehicle_from_args)

def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "simulate",
        help="simulate the truth vehicle with the lane-keeping driver and write a log (LOG_FORMAT.md)",
        description="Closed-loop simulation of the truth vehicle on a road; writes the shared CSV log "
        "with ground-truth columns (true_*).",
    )
    p.add_argument("--road", default="study1", choices=sorted(BUILTIN_ROADS) + sorted(SCENARIO_ROADS),
                   help="built-in road (default study1); identification = curves both ways + six lane changes, "
                   "repeating every 1800 m; curves = steady curves of R 250-400 m both ways, no lane changes, "
                   "repeating every 2400 m")
    p.add_argument("--duration", type=positive_float, default=60.0, help="simulated time [s] (default 60)")
    p.add_argument("--tire", choices=["pacejka", "linear"], default="pacejka", help="truth tire model")
    p.add_argument("--mu", type=positive_float, default=TireParams().mu, help="Pacejka friction coefficient")
    p.add_argument("--physics-rate", type=positive_float, default=1000.0, help="integration rate [Hz]")
    p.add_argument("--log-rate", type=positive_float, default=100.0, help="rate of the written rows [Hz] (frames are kept)")
    p.add_argument("--camera-rate", type=positive_float, default=100.0, help="camera frame rate [Hz]")
    add_noise_arguments(p, default="none", extra_help=". (estimate --camera-noise takes STANDARD DEVIATIONS)")
    p.add_argument("--effect", action="append", metavar="NAME=VALUE",
                   help="hidden physical effect in the truth model (repeatable): "
                   + "; ".join(f"{k} [{v[2]}]" for k, v in HIDDEN_EFFECTS.items())
                   + ". PlantEffects field names (" + ", ".join(f for f in PlantEffects.__dataclass_fields__ if not f.startswith("_"))
                   + ") and camera_latency / e1_bias / e2_bias also work")
    p.add_argument("--speed-profile", choices=sorted(SPEED_PROFILES), default="constant",
                   help="speed over time (v0 = the vehicle's vx): " + "; ".join(f"{k}: {v}" for k, v in SPEED_PROFILES.items()))
    p.add_argument("--seed", type=int, default=0, help="seed of the camera noise (and of numpy's global generator)")
    p.add_argument("--no-truth", action="store_true", help="omit the true_* columns")
    p.add_argument("--out", "--log", dest="out", type=Path, required=True,
                   help="output log: one CSV FILE (not a folder, unlike the other commands' --out). An existing "
                   "file is refused unless --overwrite is given")
    add_vehicle_argument(p)
    p.set_defaults(func=run, out_kind="file")


def run(args: argparse.Namespace) -> int:
    vehicle = vehicle_from_args(args)
    hidden = parse_hidden_effects(parse_assignments(args.effect, "--effect"))
    camera_kwargs = dict(hidden.camera)
    camera = camera_from_noise_args(args, args.camera_rate, **camera_kwargs)
    if not args.log_rate > 0 or args.log_rate > args.physics_rate:
        raise ParameterError("--log-rate must be > 0 and at most --physics-rate")
    road = SCENARIO_ROADS[args.road]() if args.road in SCENARIO_ROADS else args.road
    plant = hidden.make_plant(vehicle, *axle_tires(vehicle, args.tire, TireParams(mu=args.mu)))
    log = simulate(road, args.duration, vehicle=vehicle, camera=camera, physics_rate=args.physics_rate,
                   seed=args.seed, speed_profile=speed_profile(args.speed_profile, vehicle.vx), plant=plant)
    cols = hidden.apply_to_sensors(log.to_columns(include_truth=not args.no_truth))
    step = max(int(round(args.physics_rate / args.log_rate)), 1)
    keep = _rows_to_keep(cols["e1"], step)
    from ..io import check_output_file, current_run_context

    check_output_file(args.out, bool(getattr(args, "overwrite", False)), current_run_context().inputs)  # again, just before
    write_log(args.out, {k: v[keep] for k, v in cols.items()})
    print(f"wrote {keep.sum()} rows ({args.duration:g} s, {args.road}) to {args.out}")
    return 0


def _rows_to_keep(e1, step: int):
    """Every ``step``-th row, plus every row on which a camera frame arrived."""
    import numpy as np

    keep = np.zeros(len(e1), dtype=bool)
    keep[::step] = True
    keep |= np.isfinite(e1)
    return keep
