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
# # 5. Training and evaluating an excitation policy on a short budget
#
# The observer learns only the part of the tire curve the driving excites. In
# `TireLearning-Excitation-v0` a policy adds a steering offset to the lane-keeping driver on
# a straight road; its reward is the information the observer gains about the tire curve
# over a target slip range (its slope on fixed slip segments and its offset at zero slip,
# computable on a real car from the observer's own covariance), minus penalties for the lateral-acceleration limit (4 m/s^2), the lane margin
# and the steering rate. Each seed draws a truth tire the observer does not know. A safety
# filter (on by default) passes every offset through a robust a_y prediction and a per-tick
# IMU guard, so the limit holds whatever the policy asks for.
#
# Here: a very short PPO run (a few thousand steps, about a minute), then the committed
# policy (`agents/policies/ppo_excitation.zip`, the validation-best checkpoint at 950 k steps of
# a 16 min run; see `agents/README.md`) against two scripted manoeuvres tuned to the same
# limit, on a short budget.

# %%
from pathlib import Path

import numpy as np
from stable_baselines3 import PPO

from tire_learning_env import plotting
from tire_learning_env.scripted import make_manoeuvre, run_manoeuvre, run_policy
from tire_learning_env.wrappers.excitation import make_excitation_env

env = make_excitation_env()
print("action:", env.action_space, " observation:", env.observation_space.shape)
print("target slip range [deg]:", np.degrees(env.target).round(2))

# %% [markdown]
# ## A short PPO training run (real stable-baselines3, CPU)

# %%
model = PPO("MlpPolicy", env, n_steps=512, batch_size=128, seed=0, verbose=0, device="cpu")
model.learn(total_timesteps=2048)
print("trained", model.num_timesteps, "steps")

# %% [markdown]
# ## Evaluation on held-out seeds (short budget: 2 seeds x 30 s)

# %%
def sb3_policy(m):
    return lambda obs, k: m.predict(obs, deterministic=True)[0]


root = Path.cwd()
while not (root / "agents").exists() and root != root.parent:
    root = root.parent
committed = PPO.load(root / "agents" / "policies" / "ppo_excitation.zip", device="cpu")
seeds, duration = (1000, 1001), 30.0
candidates = {
    "PPO, 2048 steps (this notebook)": lambda s: run_policy(sb3_policy(model), seed=s, duration=duration),
    "PPO, committed": lambda s: run_policy(sb3_policy(committed), seed=s, duration=duration),
    "lane changes (scripted)": lambda s: run_manoeuvre(make_manoeuvre("lane_changes", amplitude=0.00296), seed=s, duration=duration),
    "no excitation": lambda s: run_manoeuvre(make_manoeuvre("none"), seed=s, duration=duration),
}
for name, run in candidates.items():
    eps = [run(s) for s in seeds]
    nrmse = np.mean([e["tire_curve_nrmse_max"] for e in eps])
    print(f"{name:32s} worse-axle NRMSE {100 * nrmse:5.2f} %  max|a_y| {max(e['max_abs_ay'] for e in eps):.2f} m/s^2  "
          f"lane violations {sum(e['lane_violation_steps'] for e in eps)}")

# %% [markdown]
# ## What the committed policy learned: the recovered curves after one episode

# %%
episode = run_policy(sb3_policy(committed), seed=1002, duration=60.0, env=env)
plant = env.unwrapped.plant
target_deg = {a: [-np.degrees(t), np.degrees(t)] for a, t in zip(("front", "rear"), env.target)}
plotting.plot_tire_curves({"learned (committed PPO, 60 s)": env.observer.axle_force}, plant.true_axle_curve, target_deg,
                          title="excitation policy: recovered vs true axle curves (target range boxed)")
print("worse-axle NRMSE over the target range: %.2f %%" % (100 * episode["tire_curve_nrmse_max"]))
