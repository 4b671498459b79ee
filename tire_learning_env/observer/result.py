"""What :func:`.estimator.estimate` returns: :class:`EstimationResult` (re-exported by :mod:`.estimator`)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..params import VehicleParams
from .config import ObserverConfig
from .gains import ObserverGains
from .neuro_adaptive import NeuroAdaptiveObserver, axle_index
from .offline import OfflineFit
from .readout import curve_gradient, stiffness_readout
from .trace import EstimateTrace

__all__ = ["EstimationResult", "AXLES"]

AXLES = ("front", "rear")


@dataclass
class EstimationResult:
    """What :func:`.estimator.estimate` returns (the same for camera, IMU and fused estimation).

    Attributes
    ----------
    sensors : {"camera", "imu", "both"}
    online : EstimateTrace
        Causal pass from the nominal curve (what a car learns on line).
    offline : EstimateTrace or None
        Pass with the refined weights held (``None`` without offline refinement).
    observer : NeuroAdaptiveObserver
        Holds the reported weights and their covariance.
    gains : ObserverGains
    fit : OfflineFit or None
    online_weights : ndarray
        Weights at the end of the causal pass.
    calibration : dict
        What was estimated from the log and what was given or assumed.
    runtime_s : dict
        Wall times of the steps [s].
    config : ObserverConfig
    file_vehicle : VehicleParams, optional
        The vehicle file when the basis was re-centred away from its stiffness
        (``calibration["weight_bounds"]``); :attr:`vehicle` is then the re-centred one.
    """

    sensors: str
    online: EstimateTrace
    offline: EstimateTrace | None
    observer: NeuroAdaptiveObserver
    gains: ObserverGains
    fit: OfflineFit | None
    online_weights: NDArray
    calibration: dict
    runtime_s: dict
    config: ObserverConfig = field(default_factory=ObserverConfig)
    file_vehicle: VehicleParams | None = None

    @property
    def trace(self) -> EstimateTrace:
        """The reported pass: offline when refined, else the causal one."""
        return self.offline if self.offline is not None else self.online

    @property
    def online_trace(self) -> EstimateTrace:
        return self.online

    @property
    def vehicle(self) -> VehicleParams:
        return self.observer.vehicle

    @property
    def weights(self) -> NDArray:
        return self.fit.weights if self.fit is not None else self.online_weights

    # -- curves -------------------------------------------------------------------------------
    def axle_force(self, alpha: ArrayLike, axle: str) -> NDArray:
        """Learned total axle force [N] (eq. 29): the reported (refined) curve."""
        return self.observer.axle_force(alpha, axle, weights=self.weights)

    def online_axle_force(self, alpha: ArrayLike, axle: str) -> NDArray:
        """The curve at the end of the causal pass [N]."""
        return self.observer.axle_force(alpha, axle, weights=self.online_weights)

    def online_curve_at(self, k: int):
        """The causal curve with the weights held at row ``k`` of the causal pass."""
        w = self.online.weights[k]
        return lambda alpha, axle: self.observer.axle_force(alpha, axle, weights=w)

    def nominal_axle_force(self, alpha: ArrayLike, axle: str) -> NDArray:
        """The vehicle file's linear axle force ``2 C alpha`` [N] (the file, also after a re-centre)."""
        v = self.file_vehicle or self.vehicle
        return 2.0 * (v.Cf if axle_index(axle) == 0 else v.Cr) * np.asarray(alpha, dtype=float)

    def _variance(self, G: NDArray) -> NDArray:
        if self.fit is not None:
            return self.fit.variance(G)
        pw = self.observer.pw
        return np.einsum("ij,jk,ik->i", G, pw, G)

    def axle_force_std(self, alpha: ArrayLike, axle: str) -> NDArray:
        """Standard deviation of the learned axle force at ``alpha`` [N]."""
        a = np.asarray(alpha, dtype=float)
        G = curve_gradient(self.observer, a.ravel(), axle_index(axle))
        return np.sqrt(np.maximum(self._variance(G), 0.0)).reshape(a.shape)

    # -- stiffness ----------------------------------------------------------------------------
    def stiffness_functionals(self) -> tuple[NDArray, list]:
        """``(g (2, nw), info)``: per-tire stiffness ``= C_nominal + g^T w`` read from the linear
        range of the learned curves (:func:`.offline.stiffness_readout`)."""
        if "_readout" not in self.calibration:
            gs, infos = [], []
            for i in (0, 1):
                g, info = stiffness_readout(self.observer, self.weights, self.trace.slip[:, i], i)
                gs.append(g)
                infos.append(info)
            self.calibration["_readout"] = (np.vstack(gs), infos)
        return self.calibration["_readout"]

    def cornering_stiffness(self) -> tuple[float, float]:
        """Per-tire cornering stiffness of the learned curves [N/rad]: half the slope at zero slip
        of a polynomial fitted over their linear range (:func:`.offline.stiffness_readout`)."""
        G, _ = self.stiffness_functionals()
        v = self.vehicle
        k = np.array([v.Cf, v.Cr]) + G @ self.weights
        return float(k[0]), float(k[1])

    def cornering_stiffness_std(self) -> tuple[float, float]:
        """Standard deviation of :meth:`cornering_stiffness` [N/rad] (sandwich covariance)."""
        G, _ = self.stiffness_functionals()
        s = np.sqrt(np.maximum(self._variance(G), 0.0))
        return float(s[0]), float(s[1])

    def stiffness_report(self) -> dict:
        """Per axle: estimate, std, two-sigma band [N/rad] (per tire), whether it is identified
        and, when not, why (``reason``).

        An axle whose read-out weights are still at their bound after the re-centring of
        :func:`.estimator.estimate` (``calibration["weight_bounds"]["not_identified"]``) is not
        identified whatever its band: the band is that of a capped curve."""
        k = self.cornering_stiffness()
        s = self.cornering_stiffness_std()
        capped = self.calibration.get("weight_bounds", {}).get("not_identified", [])
        out = {}
        for i, a in enumerate(AXLES):
            narrow = bool(2.0 * s[i] <= self.config.identifiable_rel_2sigma * abs(k[i]))
            ident = narrow and a not in capped
            if a in capped:
                reason = ("weights at their bound: the vehicle file's stiffness is probably far from the truth "
                          "(the learned curve is capped; the band is that of the capped curve)")
            elif not narrow:
                reason = f"2-sigma band wider than {self.config.identifiable_rel_2sigma:g} of the value"
            else:
                reason = None
            out[a] = {
                "identified": ident,
                "estimate_N_per_rad": float(k[i]) if ident else None,
                "value_N_per_rad": float(k[i]),
                "std_N_per_rad": float(s[i]),
                "band_2sigma_N_per_rad": [float(k[i] - 2 * s[i]), float(k[i] + 2 * s[i])],
                "relative_2sigma": float(2 * s[i] / abs(k[i])) if k[i] else float("inf"),
                "reason": reason,
            }
        return out

    @property
    def verdict(self) -> str:
        """``identified`` when both axles' stiffness is identified, else ``not_identifiable``."""
        rep = self.stiffness_report()
        return "identified" if all(r["identified"] for r in rep.values()) else "not_identifiable"

    @property
    def verdict_reason(self) -> str | None:
        """Why the verdict is not ``identified`` (per axle), ``None`` when it is."""
        rep = self.stiffness_report()
        why = [f"{a}: {r['reason']}" for a, r in rep.items() if not r["identified"]]
        return "; ".join(why) or None

    def learned_slip_range(self, n: int = 201) -> dict:
        """Per axle ``[lo, hi]`` [deg]: the contiguous slip range around zero, inside the slip the
        drive covered, where the curve's two-sigma band is within ``curve_rel_2sigma`` of the force."""
        tr = self.trace
        out = {}
        for i, a in enumerate(AXLES):
            s = tr.slip[:, i][np.isfinite(tr.slip[:, i])]
            if len(s) < 10:
                out[a] = None
                continue
            lo, hi = np.percentile(s, [0.5, 99.5])
            grid = np.linspace(min(lo, 0.0), max(hi, 0.0), n)
            F = np.abs(self.axle_force(grid, a))
            sd = self.axle_force_std(grid, a)
            ok = (2.0 * sd <= self.config.curve_rel_2sigma * F) | (np.abs(grid) < math.radians(0.05))
            j0 = int(np.argmin(np.abs(grid)))
            if not ok[j0] or self.stiffness_report()[a]["identified"] is False:
                out[a] = None
                continue
            l = j0
            while l > 0 and ok[l - 1]:
                l -= 1
            h = j0
            while h < n - 1 and ok[h + 1]:
                h += 1
            out[a] = [math.degrees(grid[l]), math.degrees(grid[h])]
        return out

    def model_error_evidence(self) -> dict | None:
        """Why the model error was reported (``None`` when it was not).

        The offline fit lowers the process noise stage by stage; the camera innovations, white at
        the stage it stopped at, turned correlated at the next one (Ljung-Box over 5 frame lags):
        the vehicle has dynamics the single-track model lacks (tire relaxation, roll, load transfer,
        a camera or steering effect). The stage, its force error [N], its NIS per degree of freedom
        and the test's statistics are returned; the band already holds the answer's change between
        the two stages.
        """
        fit = self.fit
        if fit is None or not getattr(fit, "mismatch_alternatives", None):
            return None
        turned = (getattr(fit, "force_error_calibration", None) or {}).get("model_error_stage")
        test = "camera innovations' whiteness (Ljung-Box, 5 frame lags), white at the chosen process noise"
        if turned is None:  # a fit made without the descent's records
            return {"test": test}
        return {
            "test": test,
            "chosen_force_error_N": float(fit.force_error),
            "correlated_at_force_error_N": float(turned["force_error_N"]),
            "ljung_box_q_e1_e2": [float(q) for q in turned["ljung_box_q"]],
            "ljung_box_bound": float(turned["ljung_box_bound"]),
            "nis_per_dof_there": float(turned["nis_per_dof"]),
            "meaning": ("the vehicle has dynamics the single-track model lacks (e.g. tire relaxation, roll, load "
                        "transfer); the stiffness is that of the single-track model that fits this drive best and "
                        "may differ from the steady-state cornering stiffness by more than its band"),
        }

    def summary(self) -> dict:
        """Headline figures (the ``summary`` block of ``metrics.json``)."""
        rep = self.stiffness_report()
        return {
            "sensors": self.sensors,
            "verdict": self.verdict,
            "verdict_reason": self.verdict_reason,
            "stiffness_front_N_per_rad": rep["front"]["estimate_N_per_rad"],
            "stiffness_front_2sigma_N_per_rad": rep["front"]["band_2sigma_N_per_rad"],
            "stiffness_rear_N_per_rad": rep["rear"]["estimate_N_per_rad"],
            "stiffness_rear_2sigma_N_per_rad": rep["rear"]["band_2sigma_N_per_rad"],
            # the offline fit's innovations turned correlated as the process noise fell: dynamics the model lacks
            "model_error_detected": None if self.fit is None else bool(getattr(self.fit, "mismatch_alternatives", None)),
            "model_error_evidence": self.model_error_evidence(),
            "health_final": self.online.final_health,
            "health_ok_fraction": self.online.health_fraction["ok"],
            "runtime_s": float(self.runtime_s.get("total", float("nan"))),
        }
