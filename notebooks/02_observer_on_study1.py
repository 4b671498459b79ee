# ---
# jupyter:
#   jupytext:
#     formats: py:percent
#     text_representation:
#       extension: .py
#       format_name: percent
#   kernelspec:
#     display_name: Python 3
#     language: python
#     name: python3
# ---

# %% [markdown]
# # 2. The neuro-adaptive observer on Study 1, step by step
#
# 1. the activation basis, 2. certified gains from vertex LMIs, 3. one causal run (what a car
# learns on line), 4. the offline refinement over the whole log, 5. the recovered tire curve and
# stiffness with their two-sigma bands and the identifiability verdict.

# %%
import matplotlib.pyplot as plt
import numpy as np

import tire_learning_env as tle
from tire_learning_env import plotting
from tire_learning_env.metrics import compute_metrics
from tire_learning_env.observer import HEALTH_NAMES, ObserverConfig, build_observer, estimate, make_basis
from tire_learning_env.tires import axle_tires

vehicle = tle.VehicleParams()
camera = tle.CameraParams(rate=1000.0)  # the paper's noise-free 1 kHz camera
log = tle.simulate("study1", 60.0, camera=camera)
# Study 1 knows its camera and its tires: the camera's noise and latency are given, and the
# curve is pinned to the nominal stiffness below 0.5 deg (the defaults would measure the noise
# and latency from the log and learn the stiffness)
config = ObserverConfig.for_camera(camera, stiffness_known=True)

# %% [markdown]
# ## 1. The basis
# The default `two_sided` basis has one soft clip (eq. 30) per slip segment on each side of
# zero plus a bias; a weight is the change of the curve's slope on its segment, as a fraction
# of the nominal stiffness. Its bounds give the slope box the LMIs must cover.

# %%
basis = make_basis("two_sided", vehicle)
print("activations per axle:", basis.n_per_axle)
print("segment edges [deg]:", np.degrees(np.unique(basis.upper[0][basis.upper[0] > 0])).round(3))
print("certified slope box / nominal axle stiffness:\n", (basis.force_slope_bounds() / (2 * vehicle.Cf)).round(3))

# %% [markdown]
# ## 2. Certified gains
# cvxpy solves the robust-H2 vertex LMIs for the camera's frame period and noise; numpy
# re-checks every vertex and a dense grid of slopes and speeds.

# %%
observer = build_observer(vehicle, camera, config, log.dt)
print(observer.gains.summary())

# %% [markdown]
# ## 3. One causal run from zero weights (what a car learns on its first drive)
# The observer reads `log.sensors` only: steering, speed, desired yaw rate and camera frames.
# Besides the states and the slip it reports a health flag per row from a test on its
# innovations (0 = ok).

# %%
online = observer.run(log.sensors)
t = online.t
plotting.plot_states(t, log.truth["true_state"], online.xi, title="states, causal run")
plotting.plot_slip_angles(t, log.truth["true_slip"], online.slip, title="slip angles, causal run")
plotting.plot_weights(t, online.weights, basis.n_per_axle, title="weights, causal run")
print("health:", {k: round(v, 3) for k, v in online.health_fraction.items()}, "| final:", online.final_health,
      "| codes:", dict(enumerate(HEALTH_NAMES)))

# %% [markdown]
# ## 4. Offline refinement over the whole log
# With the whole log at hand, `estimate` starts from the causal pass and fits the weights to
# every camera frame at once (a prediction-error fit with the Kalman predictor of the same
# model), then runs the observer once more with the refined weights held: the reported pass.

# %%
result = estimate(log.sensors, vehicle, camera, config, physics_dt=log.dt)
final = result.trace
print({k: v for k, v in result.calibration["offline"].items() if k in ("iterations", "updates", "nis_per_dof")})
print("wall time per step [s]:", {k: round(v, 2) for k, v in result.runtime_s.items()})
nominal = np.array([vehicle.Cf, vehicle.Cr])
plotting.plot_nonlinear_force(t, log.truth["true_force"] - log.truth["true_slip"] * 2 * nominal, final.force_nonlinear,
                              title="nonlinear part of the axle forces, refined")

# %% [markdown]
# ## 5. The recovered tire curve and the cornering stiffness, with their bands

# %%
front, rear = axle_tires(vehicle)
true_curve = lambda a, axle: (front if axle == "front" else rear).lateral_force(a)  # noqa: E731
metrics = compute_metrics(
    t=final.t, xi_hat=final.xi, slip_hat=final.slip, force_nonlinear_hat=final.force_nonlinear, truth=log.truth,
    curve=result.axle_force, true_curve=true_curve, stiffness_hat=result.cornering_stiffness(),
    stiffness_true=(vehicle.Cf, vehicle.Cr), nominal_stiffness=(vehicle.Cf, vehicle.Cr), lmi=result.gains.summary(),
)
plotting.plot_tire_curves({"learned (refined)": result.axle_force, "causal pass": result.online_axle_force},
                          true_curve, metrics["excited_slip_range_deg"], title="Study 1: learned vs true axle curves")

fig, axes = plt.subplots(1, 2, figsize=(11, 4.2))
for ax, axle in zip(axes, ("front", "rear")):
    lo, hi = np.radians(metrics["excited_slip_range_deg"][axle])
    grid = np.linspace(1.3 * lo, 1.3 * hi, 301)
    f, sd = result.axle_force(grid, axle), result.axle_force_std(grid, axle)
    ax.plot(np.degrees(grid), true_curve(grid, axle) - result.nominal_axle_force(grid, axle), "k-", label="true")
    ax.plot(np.degrees(grid), f - result.nominal_axle_force(grid, axle), "r--", label="learned")
    ax.fill_between(np.degrees(grid), f - 2 * sd - result.nominal_axle_force(grid, axle),
                    f + 2 * sd - result.nominal_axle_force(grid, axle), color="r", alpha=0.2, lw=0, label="+/-2 sigma")
    ax.axhline(0.0, color="0.5", ls=":", label="nominal")
    ax.set_xlabel("slip angle [deg]")
    ax.set_ylabel(f"{axle} axle force minus nominal [N]")
    ax.grid(alpha=0.3)
axes[0].legend(fontsize=8)
fig.suptitle("learned curve beyond the nominal line, with its two-sigma band")
plt.show()

for key in ("slip_rmse_deg", "tire_curve_nrmse", "cornering_stiffness"):
    print(key, metrics[key])
print("verdict:", result.verdict, "| learned slip range [deg]:", result.learned_slip_range())
for axle, rep in result.stiffness_report().items():
    print(axle, "stiffness %.0f +/- %.0f N/rad (2 sigma)" % (rep["value_N_per_rad"], 2 * rep["std_N_per_rad"]))
