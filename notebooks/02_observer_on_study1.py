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
# 1. the activation basis, 2. certified gains from vertex LMIs, 3. one causal run,
# 4. the least-squares warm start (SPEC §4), 5. the recovered tire curve and stiffness.

# %%
import math

import numpy as np

import tire_learning_env as tle
from tire_learning_env import plotting
from tire_learning_env.metrics import compute_metrics
from tire_learning_env.observer import ObserverConfig, build_observer, least_squares_weights, make_basis
from tire_learning_env.tires import axle_tires

vehicle = tle.VehicleParams()
camera = tle.CameraParams(rate=1000.0)  # the paper's noise-free 1 kHz camera
log = tle.simulate("study1", 60.0, camera=camera)

# %% [markdown]
# ## 1. The basis
# The default `two_sided` basis has one soft clip (eq. 30) per slip segment on each side of
# zero plus a bias; a weight is the change of the curve's slope on its segment, as a fraction
# of the nominal stiffness. Its bounds give the slope box the LMIs must cover.

# %%
basis = make_basis("two_sided", vehicle)
print("activations per axle:", basis.n_per_axle)
print("certified slope box / nominal axle stiffness:\n", (basis.force_slope_bounds() / (2 * vehicle.Cf)).round(3))

# %% [markdown]
# ## 2. Certified gains
# cvxpy solves the robust-H2 vertex LMIs; numpy re-checks every vertex.

# %%
observer = build_observer(vehicle, camera, ObserverConfig())
print(observer.gains.summary())

# %% [markdown]
# ## 3. One causal run from zero weights (what a car learns on its first drive)
# The observer reads `log.sensors` only: steering, speed, desired yaw rate and camera frames.

# %%
online = observer.run(log.sensors)
t = online.t
plotting.plot_states(t, log.truth["true_state"], online.xi, title="states, first run")
plotting.plot_slip_angles(t, log.truth["true_slip"], online.slip, title="slip angles, first run")

# %% [markdown]
# ## 4. Least-squares warm start and the second run

# %%
w0 = least_squares_weights(basis, online, linear_region=math.radians(0.5),
                           prior=basis.prior_correlation(ObserverConfig().prior_length))
observer.reset(weights=w0)
final = observer.run(log.sensors)
nominal = np.array([vehicle.Cf, vehicle.Cr])
plotting.plot_nonlinear_force(t, log.truth["true_force"] - log.truth["true_slip"] * 2 * nominal, final.force_nonlinear,
                              title="nonlinear part of the axle forces")
plotting.plot_weights(t, final.weights, basis.n_per_axle, title="weights")

# %% [markdown]
# ## 5. The recovered tire curve and the cornering stiffness

# %%
front, rear = axle_tires(vehicle)
true_curve = lambda a, axle: (front if axle == "front" else rear).lateral_force(a)  # noqa: E731
metrics = compute_metrics(
    t=t, xi_hat=final.xi, slip_hat=final.slip, force_nonlinear_hat=final.force_nonlinear, truth=log.truth,
    curve=observer.axle_force, true_curve=true_curve, stiffness_hat=observer.cornering_stiffness(),
    stiffness_true=(vehicle.Cf, vehicle.Cr), nominal_stiffness=(vehicle.Cf, vehicle.Cr), lmi=observer.gains.summary(),
)
plotting.plot_tire_curves({"learned": observer.axle_force}, true_curve, metrics["excited_slip_range_deg"],
                          title="Study 1: learned vs true axle curves")
for key in ("slip_rmse_deg", "tire_curve_nrmse", "cornering_stiffness"):
    print(key, metrics[key])
