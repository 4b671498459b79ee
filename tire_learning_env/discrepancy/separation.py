"""Confounded explanations: which manoeuvre separates them, checked by simulating it.

When two candidate effects fit a log about equally well (:func:`.workflow.analyze` gives the
verdict ``ambiguous``), the log cannot say which one is real. What can is another drive
that makes their signatures differ. :data:`SEPARATING_MANOEUVRES` gives, per pair, the
manoeuvre and why it separates them, with a *recipe* that this module can simulate:

- ``speed``: drive the same road at a varying speed (``sine`` profile: +/-25 %);
- ``imu``: log the IMU's lateral acceleration and yaw rate as well;
- ``step_steer``: add step-like steering (the lane changes of the identification road).

:func:`verify_separation` simulates the proposal with each candidate as the truth, at its
fitted size, on the log's own road (the logged curvature against distance,
:class:`LoggedRoad`), at the log's speed, camera rate and noise (estimated from the log), and
analyses each simulated log with only the two candidates: the proposal is verified when each
truth is named, unambiguously, in its own log.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..roads import Road

__all__ = ["SEPARATING_MANOEUVRES", "LoggedRoad", "propose", "verify_separation", "hidden_effects_of"]

_SPEED = (
    "drive the same curves at another speed (a speed that varies by at least +/-20 %, e.g. the same road at 0.75 "
    "and 1.25 times the speed): the lateral force of the superelevation, m g sin(e(kappa)), does not change with "
    "speed while the force the tires must supply, m vx^2 kappa, does, so the share the road takes changes with speed; "
    "a stiffness or steering-ratio error scales the tire side of the balance by the same factor at every speed"
)
_IMU = (
    "log the lateral acceleration (IMU): the accelerometer feels a crosswind or a tire-force error but not the "
    "gravity component along a banked road"
)
_STEP = (
    "a step steer (a fast steering step of about 0.02 rad, or a quick lane change): relaxation delays the lateral "
    "force by relaxation_length / vx and so the whole response, latency only delays the camera's view of it (and "
    "an IMU yaw rate is not delayed by it)"
)
_RATIO = (
    "drive the same curves at another speed: a steering-ratio error scales the kinematic steering L kappa that "
    "dominates at low speed, a stiffness error only the dynamic (understeer) part that grows with vx^2"
)

#: pair of effects -> (recipe, manoeuvre text); the recipe is what :func:`verify_separation` simulates
SEPARATING_MANOEUVRES: dict[frozenset, tuple[str, str]] = {
    frozenset({"road_superelevation", "cornering_stiffness_scale"}): ("speed", _SPEED),
    frozenset({"road_superelevation", "steering_ratio_error"}): ("speed", _SPEED),
    frozenset({"road_superelevation", "speed_dependent_stiffness"}): ("speed", _SPEED),
    frozenset({"road_superelevation", "load_transfer"}): ("speed", _SPEED),
    frozenset({"cornering_stiffness_scale", "steering_ratio_error"}): ("speed", _RATIO),
    frozenset({"road_bank", "crosswind"}): ("imu", _IMU),
    frozenset({"road_superelevation", "road_bank"}): ("speed", _SPEED),
    frozenset({"camera_latency", "tire_relaxation"}): ("step_steer", _STEP),
}
_DEFAULT = (
    "speed",
    "a drive with a speed that varies by at least +/-20 % and step-like steering (lane changes): most library effects "
    "scale differently with speed and with the steering rate",
)


def propose(a: str, b: str) -> dict:
    """The separating manoeuvre of effects ``a`` and ``b``: ``{"recipe", "manoeuvre"}``."""
    recipe, text = SEPARATING_MANOEUVRES.get(frozenset({a, b}), _DEFAULT)
    return {"effects": [a, b], "recipe": recipe, "manoeuvre": text}


def hidden_effects_of(name: str, parameters: dict) -> dict[str, float]:
    """``--effect`` assignments (:data:`tire_learning_env.scenarios.HIDDEN_EFFECTS`) that put a library effect with these
    fitted parameters into the truth model."""
    if name == "cornering_stiffness_scale":
        return {"cornering_stiffness_scale_front": parameters["front"], "cornering_stiffness_scale_rear": parameters["rear"]}
    if name == "road_superelevation":
        return {"superelevation_rate": parameters["rate"], "superelevation_cap": parameters["cap"]}
    return {name: float(next(iter(parameters.values())))}


class LoggedRoad(Road):
    """The road of a log: its curvature [1/m] against the distance travelled (``int vx dt``), repeated.

    Parameters
    ----------
    t, vx, kappa : array_like
        Time [s], speed [m/s] and path curvature [1/m] per row of the log.
    """

    def __init__(self, t: ArrayLike, vx: ArrayLike, kappa: ArrayLike, lane_width: float = 3.7) -> None:
        t = np.asarray(t, dtype=float)
        vx = np.asarray(vx, dtype=float)
        s = np.concatenate([[0.0], np.cumsum(0.5 * (vx[1:] + vx[:-1]) * np.diff(t))])
        keep = np.concatenate([[True], np.diff(s) > 1e-6])
        self.s = s[keep]
        self.kappa = np.asarray(kappa, dtype=float)[keep]
        self.period = float(self.s[-1])
        self.rate = np.gradient(self.kappa, self.s) if len(self.s) > 1 else np.zeros_like(self.s)
        self.lane_width = lane_width

    def curvature(self, s: ArrayLike) -> NDArray:
        return np.interp(np.mod(np.asarray(s, dtype=float), self.period), self.s, self.kappa)

    def curvature_rate(self, s: ArrayLike) -> NDArray:
        return np.interp(np.mod(np.asarray(s, dtype=float), self.period), self.s, self.rate)


def _simulated_log(result, effects: dict, recipe: str, seed: int):
    """A log like ``result``'s (road, speed, duration, camera rate and noise) with ``effects`` hidden."""
    from ..io import DrivingLog
    from ..params import CameraParams, TireParams
    from ..simulation import simulate
    from ..tires import axle_tires
    from ..scenarios import IdentificationRoad, parse_hidden_effects, speed_profile

    d = result.data
    vehicle = replace(result.vehicle, vx=float(np.median(d.vx)))
    frames = d.meas_row[d.meas_chan == 0]
    rate = 1.0 / float(np.median(np.diff(d.t[frames])))
    duration = float(min(d.t[-1] - d.t[0], 90.0))
    hidden = parse_hidden_effects(effects)
    e1n = float(d.sigma_estimated[0]) if math.isfinite(d.sigma_estimated[0]) else 0.0
    e2n = float(d.sigma_estimated[1]) if math.isfinite(d.sigma_estimated[1]) else 0.0
    camera = CameraParams(rate=rate, noise="gaussian", e1_noise=e1n, e2_noise=e2n, **hidden.camera)
    road = IdentificationRoad() if recipe == "step_steer" else LoggedRoad(d.t, d.vx, d.kappa)
    kind = result.tire.get("kind", "pacejka")
    tp = TireParams(mu=result.tire.get("mu", TireParams().mu)) if kind == "pacejka" else TireParams()
    plant = hidden.make_plant(vehicle, *axle_tires(vehicle, kind, tp))
    log = simulate(road, duration, vehicle=vehicle, camera=camera, physics_rate=1000.0, seed=seed,
                   speed_profile=speed_profile("sine" if recipe == "speed" else "constant", vehicle.vx), plant=plant)  # fmt: skip
    cols = hidden.apply_to_sensors(log.to_columns(include_truth=False))
    step = max(int(round(1000.0 / min(100.0, 1.0 / float(np.median(np.diff(d.t)))))), 1)
    keep = np.zeros(len(cols["t"]), dtype=bool)
    keep[::step] = True
    keep |= np.isfinite(cols["e1"])
    sensors = {k: v[keep] for k, v in cols.items()}
    imu = recipe == "imu" or any(c in d.channels for c in ("yaw_rate", "ay"))
    if not imu:
        sensors.pop("yaw_rate", None)
        sensors.pop("ay", None)
    return DrivingLog(sensors=sensors, truth={}, kind="camera", source=f"simulated separating manoeuvre ({recipe})")


def verify_separation(result, a: dict, b: dict, recipe: str, seed: int = 7) -> dict:
    """Simulate the separating manoeuvre with ``a`` and then ``b`` (effect entries: ``name``,
    ``parameters``) as the truth and analyse each log with only the two candidates.

    Returns ``{"verified": bool, "runs": [...]}``; each run gives the truth, the verdict and
    the BIC advantage of the true candidate over the other (positive = the truth fits better).
    """
    from .workflow import analyze

    kind = result.tire.get("kind")
    if kind not in ("pacejka", "linear"):
        return {"verified": None, "reason": f"the nominal tire ({kind}) cannot drive the simulator", "runs": []}
    runs = []
    ok = True
    for truth, other in ((a, b), (b, a)):
        log = _simulated_log(result, hidden_effects_of(truth["name"], truth["parameters"]), recipe, seed)
        cfg = replace(result.config, verify_separation=False, use_imu=True)
        res = analyze(log, result.vehicle, kind, cfg, progress=False,
                      candidates=(truth["name"], other["name"]))  # fmt: skip
        named = sorted(e["name"] for e in res.effects)
        advantage = math.nan
        for st in res.selection.steps:
            info = st.tried
            if truth["name"] in info and other["name"] in info and "chi2" in info[truth["name"]] and "chi2" in info[other["name"]]:
                n = res.data.n_measurements
                bic = {k: info[k]["chi2"] + info[k]["k"] * math.log(n) for k in (truth["name"], other["name"])}
                advantage = float(bic[other["name"]] - bic[truth["name"]])
                break
        separated = res.verdict == "found" and named == [truth["name"]]
        ok &= separated
        runs.append({"truth": truth["name"], "truth_parameters": truth["parameters"], "verdict": res.verdict,
                     "named": named, "bic_advantage_of_truth": advantage, "separated": separated})  # fmt: skip
    return {"verified": bool(ok), "runs": runs, "seed": seed}
