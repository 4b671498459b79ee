"""``tire-learning reproduce``: run the paper's studies and write metrics and figures."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from tqdm import tqdm

from ._common import add_noise_arguments, camera_from_noise_args, positive_float


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "reproduce",
        help="reproduce the paper's studies (metrics.json + figures)",
        description="Simulate the study, run the neuro-adaptive observer (and optionally the UKF "
        "baseline) on the camera data only, score against ground truth, and write DIR/metrics.json "
        "and PNG figures. DIR is replaced atomically.",
    )
    which = p.add_mutually_exclusive_group(required=True)
    which.add_argument("--study", type=int, choices=[1, 2, 3], help="study number")
    which.add_argument("--all", action="store_true", help="every study plus an index report")
    p.add_argument("--out", type=Path, required=True, help="output folder (see --overwrite)")
    p.add_argument("--baseline", choices=["ukf"], default=None, help="also score the joint UKF baseline")
    p.add_argument("--camera-rate", type=positive_float, default=None, help="camera frame rate [Hz] (default: the study's)")
    add_noise_arguments(p, default=None, extra_help=" (default: the study's camera; the same grammar as simulate)")
    p.add_argument("--basis", choices=["two_sided", "paper"], default=None, help="activation basis preset")
    p.add_argument("--duration", type=positive_float, default=None, help="simulated time [s] (default 60)")
    p.add_argument("--seed", type=int, default=None, help="seed of the simulated camera noise (default: the study's)")
    p.set_defaults(func=run)


def _spec(study: int, args: argparse.Namespace):
    from dataclasses import replace

    from ..studies import study_spec

    spec = study_spec(study, args.duration)
    if args.noise in ("uniform", "gaussian"):
        spec = spec.with_camera(args.camera_rate, camera_from_noise_args(args, args.camera_rate or spec.camera.rate))
    elif args.camera_rate is not None or args.noise is not None:
        spec = spec.with_camera(args.camera_rate, args.noise)
    if args.basis is not None:
        spec = replace(spec, config=spec.config.replace(basis=args.basis))
    if args.seed is not None:
        spec = replace(spec, seed=args.seed)
    return spec


def run(args: argparse.Namespace) -> int:
    from ..studies import run_study

    if args.all:
        from ..report import reproduce_all

        ignored = [f"--{k.replace('_', '-')}" for k in ("camera_rate", "noise", "basis", "seed")
                   if getattr(args, k) is not None]
        if ignored:
            from ..params import ParameterError

            raise ParameterError(f"--all runs every study as published; {', '.join(ignored)} apply with --study N only")
        reproduce_all(args.out, baseline=args.baseline, duration=args.duration)
        print(f"wrote every study and {args.out / 'index.md'}")
        return 0
    spec = _spec(args.study, args)
    with tqdm(total=1, desc=f"study {args.study}", disable=None) as bar:
        metrics = run_study(spec, args.out, baseline=args.baseline)
        bar.update()
    keys = ("slip_rmse_deg", "tire_curve_nrmse", "cornering_stiffness", "lmi")
    print(json.dumps({k: metrics[k] for k in keys}, indent=2))
    print(f"wrote {args.out}/metrics.json and figures")
    return 0
