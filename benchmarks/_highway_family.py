"""The generalisation benchmark's highway-env traffic family (``highway_traffic``; issue 15, item 5).

Scenario ``i`` is drawn by :func:`sample_highway` from the benchmark's generator, driven in one of
the package's highway-env scenes with the truth vehicle as the ego car (:func:`build_highway`),
and scored by ``bench_generalization.run_scenario`` exactly as the camera families are.

- **scene** ``highway`` (half the draws): ``TireLearning-Highway-v0``, 3 lanes of 4 m, 6 IDM/MOBIL
  cars, the ego's IDM toward a target speed of 20-33 m/s, and lane changes on a scripted discrete
  action (``lane_change="action"``) every 4-8 s (first after 3-5 s) toward a random neighbouring
  lane: at each the target lane switches and the camera's ``e1`` jumps by the lane width.
- **scene** ``racetrack``: ``TireLearning-Racetrack-v0`` (highway-env's racetrack, arcs of 15-30 m
  radius, 2 lanes of 5 m, 2 IDM/MOBIL cars, MOBIL lane changes), target speed 10-14 m/s, lowered
  before curves to a lateral acceleration of 3.5-5.5 m/s^2; the track's joins step ``e1`` by up to
  0.22 m (a highway-env geometry artefact, ``docs/highway.md``) and lane changes by 5 m.
- **truth**: the vehicle file (sedan, CommonRoad 1 or 2 as an equivalent bicycle, or the light race
  car) with low-order Pacejka axle tires of random shape and a stiffness within +/-20 % of the
  file's, drawn as in family A (``tires`` of the env's config).
- **camera** as in every camera family (10-100 Hz, gaussian or uniform noise of 0.5-2 cm and
  0.05-1 deg, latency 0-100 ms, 0-20 % dropped frames), rows at the 1 kHz physics rate.
- **log**: 30-45 s (``--quick``: 12 s, camera <= 25 Hz), the env's per-tick ``sensor_log`` rows
  concatenated (the estimators' input) and ``truth_log`` (scoring only).

A drive that ends early (collision, lane departure) or loses control is redrawn as in the other
families (``truth_summary`` ``valid`` False).
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

HIGHWAY = "highway_traffic"
SCENES = ("highway", "racetrack")


def sample_highway(sc: dict, rng: np.random.Generator, quick: bool, pacejka_truth, camera) -> dict:
    """Fill scenario ``sc`` of the ``highway_traffic`` family from ``rng`` (module docstring).

    Parameters
    ----------
    sc : dict
        The scenario so far (family, index, seeds).
    rng : numpy.random.Generator
        The scenario's generator.
    quick : bool
        Short logs (12 s, camera <= 25 Hz).
    pacejka_truth, camera : callable
        ``rng -> dict``: the benchmark's truth and camera draws (shared with the other families).

    Returns
    -------
    dict
        ``sc`` with ``vehicle``, ``truth``, ``scene``, ``duration_s``, ``speed`` and ``camera``.
    """
    sc["vehicle"] = str(rng.choice(["sedan", "commonroad_1", "commonroad_2", "race_car"]))
    sc["truth"] = {"plant": "low_order_pacejka", **pacejka_truth(rng)}
    scene = str(rng.choice(SCENES))
    if scene == "highway":
        vx = float(rng.uniform(20.0, 33.0))
        first = float(rng.uniform(3.0, 5.0))
        gaps = [float(rng.uniform(4.0, 8.0)) for _ in range(12)]
        sc["scene"] = {"kind": "highway", "lane_change_times_s": list(np.round(first + np.r_[0.0, np.cumsum(gaps)], 3)),
                       "lane_change_up": [bool(rng.random() < 0.5) for _ in range(13)],
                       "vehicles_count": 6, "initial_lane_id": int(rng.integers(0, 3))}  # fmt: skip
        sc["speed"] = {"vx": vx, "profile": "idm", "target_speed": vx}
    else:
        vx = float(rng.uniform(10.0, 14.0))
        sc["scene"] = {"kind": "racetrack", "max_lateral_acceleration": float(rng.uniform(3.5, 5.5)), "vehicles_count": 2}
        sc["speed"] = {"vx": vx, "profile": "idm", "target_speed": vx}
    sc["duration_s"] = float(rng.uniform(30.0, 45.0))
    sc["camera"] = camera(rng)
    if quick:
        sc["duration_s"] = 12.0
        sc["camera"]["rate"] = min(sc["camera"]["rate"], 25.0)
    return sc


def _env(sc: dict, truth_vehicle, tires):
    import gymnasium as gym

    import tire_learning_env  # noqa: F401  (registers the ids)
    from tire_learning_env.params import CameraParams

    scene = sc["scene"]
    cfg = {"vehicle": truth_vehicle, "tires": tires, "camera": CameraParams(**sc["camera"]),
           "target_speed": sc["speed"]["target_speed"], "initial_speed": sc["speed"]["target_speed"],
           "vehicles_count": scene["vehicles_count"]}  # fmt: skip
    if scene["kind"] == "highway":
        cfg.update(lane_change="action", initial_lane_id=scene["initial_lane_id"])
        return gym.make("TireLearning-Highway-v0", config=cfg, max_episode_steps=10**7)
    cfg.update(max_lateral_acceleration=scene["max_lateral_acceleration"])
    return gym.make("TireLearning-Racetrack-v0", config=cfg, max_episode_steps=10**7)


def drive(sc: dict, truth_vehicle, tires) -> tuple[dict, dict, dict]:
    """Drive the scene for ``sc["duration_s"]``; ``(sensors, truth, events)`` with the per-tick rows
    concatenated and the drive's events (lane switches, collision, departure, simulated length)."""
    env = _env(sc, truth_vehicle, tires)
    try:
        _, info = env.reset(seed=int(sc["sim_seed"]))
        u = env.unwrapped
        steps = int(round(sc["duration_s"] * u.policy_rate))
        scene = sc["scene"]
        changes = {int(round(t * u.policy_rate)): up for t, up in
                   zip(scene.get("lane_change_times_s", []), scene.get("lane_change_up", []))}  # fmt: skip
        lanes = 3
        S, T, switches, rows = [], [], [], 0
        end = {"crashed": False, "lane_departure": False}
        for k in range(steps):
            if scene["kind"] == "highway":
                a = 0
                if k in changes:  # toward a neighbouring lane that exists
                    lane = int(info["target_lane_index"][2])
                    up = changes[k] if 0 < lane < lanes - 1 else lane == 0
                    a = 2 if up else 1
            else:
                a = np.zeros(env.action_space.shape, dtype=np.float32)
            _, _, term, trunc, info = env.step(a)
            sw = info["lane_switches"]
            for j in range(len(sw["row"])):
                switches.append({"row": int(sw["row"][j]) + rows, "lane_change": bool(sw["lane_change"][j]),
                                 "e1_jump_m": float(sw["e1_jump"][j])})  # fmt: skip
            S.append(info["sensor_log"])
            T.append(info["truth_log"])
            rows += len(info["sensor_log"]["t"])
            if term or trunc:
                end = {"crashed": bool(info.get("crashed")), "lane_departure": bool(info.get("lane_departure"))}
                break
    finally:
        env.close()
    sensors = {key: np.concatenate([np.asarray(s[key], dtype=float) for s in S]) for key in S[0]}
    truth = {key: np.concatenate([np.asarray(s[key]) for s in T]) for key in T[0]}
    events = {"simulated_s": float(rows / u.physics_rate), "requested_s": float(sc["duration_s"]), "rows": rows, **end,
              "lane_switches": switches,
              "lane_changes": sum(s["lane_change"] for s in switches),
              "largest_e1_step_m": max((abs(s["e1_jump_m"]) for s in switches), default=0.0)}  # fmt: skip
    return sensors, truth, events


def build_highway(sc: dict, vehicle_of):
    """``(log, plant, truth_vehicle, nominal_vehicle, true_curve, true_stiffness)`` of a highway scenario,
    as ``bench_generalization.build`` returns them (``log.sensors``, ``log.truth``, ``log.events``).

    Parameters
    ----------
    sc : dict
        The scenario (:func:`sample_highway`).
    vehicle_of : callable
        ``(name, vx) -> VehicleParams``: the benchmark's vehicle files.
    """
    from _bench_common import pacejka_truth
    from tire_learning_env.dynamics import BicyclePlant

    nominal = vehicle_of(sc["vehicle"], sc["speed"]["vx"])  # the vehicle file
    truth_vehicle, tires = pacejka_truth(nominal, sc["truth"])
    plant = BicyclePlant(truth_vehicle, *tires)  # the env builds the same plant from the same tires
    sensors, truth, events = drive(sc, truth_vehicle, tires)
    log = SimpleNamespace(sensors=sensors, truth=truth, events=events)
    return log, plant, truth_vehicle, nominal, plant.true_axle_curve, tuple(float(x) for x in plant.true_cornering_stiffness())


def highway_truth_summary(log, plant, sc: dict, truth_summary) -> dict:
    """``truth_summary`` of the benchmark plus the drive's events.

    The truth ``e1`` is relative to the target lane, which switches at a lane change (``e1`` then
    starts a lane width off), so the benchmark's "more than 1.5 m off the path" test is replaced by
    the env's own corridor test: ``valid`` is False when the truth is not finite, a slip passed its
    tire's peak, or the drive ended early (collision or lane departure; less than 95 % of its length).
    """
    out = truth_summary(log, plant, sc)
    ev = log.events
    out["drive"] = {k: ev[k] for k in ("simulated_s", "crashed", "lane_departure", "lane_changes", "largest_e1_step_m")}
    out["drive"]["lane_switches"] = len(ev["lane_switches"])
    peak = out.get("tire_peak_slip_deg")
    beyond = peak is not None and any(out["max_abs_slip_deg"][j] > peak[j] for j in range(2))
    ended = ev["crashed"] or ev["lane_departure"] or ev["simulated_s"] < 0.95 * ev["requested_s"]
    out["valid"] = bool(out["finite"] and not beyond and not ended)
    return out
