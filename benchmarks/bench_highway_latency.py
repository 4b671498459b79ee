"""How the camera latency's estimate moves a highway drive's stiffness (issue 15), printed as JSON.

One scenario of the generalisation benchmark's ``highway_traffic`` family
(``bench_generalization.sample_scenario("highway_traffic", i, 15, False)``), its camera changed by
``--variant`` (e.g. ``rate=100,latency=0,dropout_probability=0``; keys ``rate``, ``latency``,
``e1_noise``, ``e2_noise``, ``dropout_probability``, ``noise``), estimated twice with defaults: once as a new
user would (the latency estimated from the log) and once told the true latency
(``ObserverConfig(latency=...)``). Per run: the latency found and its standard deviation, the stiffness
error and its two-sigma band [%], the verdict. The README's highway-family diagnosis quotes these.

Run: ``python benchmarks/bench_highway_latency.py --scenario 2 --variant "" --variant
"rate=100,latency=0,dropout_probability=0"`` (about 20 s per variant).
"""

from __future__ import annotations

import argparse

import numpy as np

import _highway_family as hf
import bench_generalization as bg
from _bench_common import emit

CAMERA_KEYS = {"rate": float, "latency": float, "e1_noise": float, "e2_noise": float, "dropout_probability": float,
               "noise": str}  # fmt: skip


def parse_variant(text: str) -> dict:
    """``"k=v,k=v"`` -> ``{k: v}`` for the camera keys (an unknown key is an error naming it)."""
    out = {}
    for item in filter(None, (p.strip() for p in text.split(","))):
        key, _, value = item.partition("=")
        if key not in CAMERA_KEYS:
            raise SystemExit(f"unknown camera key {key!r} in --variant (known: {', '.join(CAMERA_KEYS)})")
        out[key] = CAMERA_KEYS[key](value)
    return out


def run(i: int, variant: dict, details: bool = False) -> list[dict]:
    """The scenario with its camera changed by ``variant``, estimated without and with the true latency
    (``details``: each record also holds the estimate's ``calibration["latency"]``)."""
    from tire_learning_env.observer import ObserverConfig, estimate

    sc0 = bg.sample_scenario(hf.HIGHWAY, i, 15, False)
    sc0["camera"].update(variant)
    sc, built, _, rejected = bg._build_with_redraws(
        sc0, lambda s: hf.build_highway(s, bg._vehicle), lambda b: hf.highway_truth_summary(b[0], b[1], sc0, bg.truth_summary))
    log, _, _, nominal, _, k_true = built
    kt = np.asarray(k_true)
    out = []
    for told in (False, True):
        cfg = ObserverConfig(sensors="camera", latency=sc["camera"]["latency"]) if told else ObserverConfig(sensors="camera")
        res = estimate(log.sensors, nominal, config=cfg)
        k, sd = np.asarray(res.cornering_stiffness()), np.asarray(res.cornering_stiffness_std())
        lat = res.calibration["latency"]
        out.append({"scenario": i, "scene": sc["scene"]["kind"], "camera": sc["camera"], "redraws": len(rejected),
                    "latency_told": told, "latency_true_ms": 1e3 * sc["camera"]["latency"],
                    "latency_used_ms": 1e3 * lat["latency_s"],
                    "latency_std_ms": None if "latency_std_s" not in lat else 1e3 * lat["latency_std_s"],
                    "stiffness_error_pct": (100.0 * (k / kt - 1.0)).tolist(), "band_2sigma_pct": (200.0 * sd / kt).tolist(),
                    "covered_2sigma": (np.abs(k - kt) <= 2.0 * sd).tolist(), "verdict": res.verdict})  # fmt: skip
        if details:
            out[-1]["calibration_latency"] = lat
    return out


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", type=int, default=2, help="highway_traffic scenario index (seed 15)")
    ap.add_argument("--variant", action="append", default=None,
                    help='camera changes "k=v,..." (repeatable; "" = the scenario as drawn)')
    args = ap.parse_args(argv)
    variants = args.variant if args.variant is not None else [""]
    result = {"benchmark": "highway_latency", "scenario": args.scenario,
              "runs": [r for v in variants for r in run(args.scenario, parse_variant(v))]}  # fmt: skip
    emit(result)
    return result


if __name__ == "__main__":
    main()
