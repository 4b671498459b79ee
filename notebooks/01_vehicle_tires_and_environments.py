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
# # 1. The truth vehicle, its tires and the environments
#
# The truth vehicle is the error-coordinate bicycle model of SPEC §1 (the paper's eqs. 1-8):
# state `[e1, e1_dot, e2, e2_dot]`, lateral offset and heading error relative to the road,
# driven by the front steering `delta` and the road's desired yaw rate `vx * kappa`.
# Its axle tires are Pacejka Magic Formula curves whose slope at zero slip is the
# paper's cornering stiffness `2 C`, and whose peak is `mu * F_z`.

# %%
import numpy as np

import tire_learning_env as tle
from tire_learning_env import plotting
from tire_learning_env.dynamics import error_state_matrices
from tire_learning_env.tires import axle_tires

vehicle = tle.VehicleParams()  # the paper's D-class sedan, SI units
print(vehicle)
A, B1, B2, B3, F, C = error_state_matrices(vehicle)
print("A =\n", A.round(3))

# %% [markdown]
# ## Tire models
# Linear, and Pacejka with two friction levels. The nonlinear part the observer must learn
# is the gap between the Pacejka curve and the linear one.

# %%
front_linear, _ = axle_tires(vehicle, "linear")
front_dry, _ = axle_tires(vehicle, "pacejka", tle.TireParams(mu=1.0))
front_wet, _ = axle_tires(vehicle, "pacejka", tle.TireParams(mu=0.6))
plotting.plot_tire_models(
    {"linear 2C": front_linear.lateral_force, "Pacejka, mu = 1.0": front_dry.lateral_force,
     "Pacejka, mu = 0.6": front_wet.lateral_force},
    title="front axle lateral force",
)

# %% [markdown]
# ## A closed-loop drive
# `simulate` runs truth plant + lane camera + built-in lane-keeping driver at 1 kHz. The
# Study 1 road: straight, then R = 300 m, then R = 250 m.

# %%
log = tle.simulate("study1", 60.0)
geometry = tle.make_road("study1").geometry(1800.0)
plotting.plot_path_and_steering(geometry, log.sensors["t"], log.sensors["delta"], title="Study 1 road")
print("max |e1| [m]:", np.abs(log.truth["true_state"][:, 0]).max().round(4))
print("slip range [deg]:", np.degrees(log.truth["true_slip"].min(0)).round(2), np.degrees(log.truth["true_slip"].max(0)).round(2))

# %% [markdown]
# ## The Gymnasium environments
# Every id is registered on import. The picture is the env's own `rgb_array` render.

# %%
import gymnasium as gym
import matplotlib.pyplot as plt

print(sorted(tle.ENV_IDS))
env = gym.make("TireLearning-LaneChange-v0", render_mode="rgb_array")
obs, info = env.reset(seed=0)
for _ in range(100):
    obs, reward, terminated, truncated, info = env.step(np.zeros(1, dtype=np.float32))
print("observation:", dict(zip(tle.envs.OBSERVATION_NAMES, obs.round(4))))
print("ground truth in info:", sorted(k for k in info if k.startswith("true")))
plt.imshow(env.render())
plt.axis("off")
plt.title("TireLearning-LaneChange-v0 after 5 s")
plt.show()
