"""The excitation safety filter: decision time, and how far the stiffness-box corners cover its interior.

- ``decide_us_median``: one :meth:`LateralAccelerationFilter.decide` (the compiled pass over
  the cached predictions), in microseconds (median over states).
- ``interior``: the filter checks only the four corners of the +/-20 % front/rear
  stiffness box. For random states and requested offsets, the applied offset is re-predicted
  at every point of a 9 x 9 grid over the box, for each continuation (release, hold) that the
  corner check accepted. A decision counts as covered when one such continuation stays within
  ``ay_limit - margin`` at every grid point. Reported: how many decisions are not covered, and by
  how much the best accepted continuation exceeds the bound somewhere inside the box. For this to
  matter it must stay well below the margin (0.64 m/s^2 with the excitation camera).

Run: ``python benchmarks/bench_safety_filter.py`` (about 10 s).
"""

from __future__ import annotations

import time

from _bench_common import emit

import numpy as np  # noqa: E402


def main() -> None:
    from tire_learning_env.params import DriverParams, VehicleParams
    from tire_learning_env.wrappers.excitation import EXCITATION_CAMERA
    from tire_learning_env.wrappers.safety import LateralAccelerationFilter

    vehicle, driver, vx = VehicleParams(), DriverParams(), VehicleParams().vx
    filt = LateralAccelerationFilter(vehicle, driver, 4.0, 0.05, EXCITATION_CAMERA)
    bound = filt.ay_limit - filt.margin(vx)
    rng = np.random.default_rng(0)
    n_cases = 2000
    states = [rng.normal(size=4) * [0.2, 0.2, 0.004, 0.02] for _ in range(n_cases)]
    integrals = rng.normal(size=n_cases) * 0.05
    requests = rng.uniform(-0.05, 0.05, size=n_cases)
    kappas = rng.normal(size=n_cases) * 0.001  # road curvature up to about 3 m/s^2 at 30 m/s

    filt.decide(0.01, states[0], 0.0, vx, 0.0, max_offset=0.05)  # compile, fill the cache
    decide_us, decisions = [], []
    for s, z, u, k in zip(states, integrals, requests, kappas):
        t0 = time.perf_counter()
        d = filt.decide(u, s, z, vx, k, max_offset=0.05)
        decide_us.append(1e6 * (time.perf_counter() - t0))
        decisions.append(d)

    # the continuations the corner check accepted, per decision (those beyond the limit at u = 0
    # are skipped: there the filter only keeps the offset from making things worse)
    accepted = {}
    for i, (s, z, d) in enumerate(zip(states, integrals, decisions)):
        if d.driver_beyond_limit:
            continue
        corners = np.max(np.abs(filt.predict(d.applied, s, z, vx, kappas[i])), axis=(0, 2))  # per continuation
        accepted[i] = np.flatnonzero(corners <= bound + 1e-9)
    # the same decisions re-predicted inside the box (one exact-stiffness filter per grid point)
    grid = np.linspace(1.0 - filt.stiffness_uncertainty, 1.0 + filt.stiffness_uncertainty, 9)
    inside = {i: np.zeros(len(filt.BACKUPS)) for i in accepted}  # worst peak over the grid per continuation
    for sf in grid:
        for sr in grid:
            point = LateralAccelerationFilter(vehicle, driver, 4.0, 0.05, EXCITATION_CAMERA)
            point.vertices = ((sf, sr),)  # one stiffness point; the driver keeps the nominal feed-forward
            for i in accepted:
                peak = np.max(np.abs(point.predict(decisions[i].applied, states[i], integrals[i], vx, kappas[i])),
                              axis=2)[0]  # fmt: skip
                inside[i] = np.maximum(inside[i], peak)
    excesses = [float(np.min(inside[i][accepted[i]])) - bound for i in accepted if len(accepted[i])]
    not_covered = [e for e in excesses if e > 1e-9]
    emit(
        {
            "benchmark": "safety_filter",
            "decide_us_median": round(float(np.median(decide_us)), 1),
            "bound_m_s2": round(bound, 3),
            "margin_m_s2": round(filt.margin(vx), 3),
            "interior": {
                "grid": "9 x 9 over the +/-20 % front/rear stiffness box",
                "decisions_checked": len(excesses),
                "decisions_skipped_driver_beyond_limit": len(states) - len(accepted),
                "not_covered": len(not_covered),
                "max_excess_over_bound_m_s2": round(max(not_covered, default=0.0), 4),
            },
        }
    )


if __name__ == "__main__":
    main()
