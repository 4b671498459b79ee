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
# # 3. Studies 2 and 3 on the high-order vehicle, beside the joint UKF
#
# The truth is CommonRoad's 29-state multi-body model (roll, pitch, load transfer,
# PAC2002 combined-slip tires, 0.45 m relaxation length), which the observer never sees.
# Study 2: the observer assumes a cornering stiffness 13.6 % / 16.5 % too high (the paper's
# ratios). Study 3: known stiffness, the paper's uniform noise (+/-1 cm, +/-1 deg).
# Each study is scored against the *effective* axle characteristic (what a bicycle model
# can represent; roll camber makes it stiffer than the tire, see docs/high_order.md §6) and
# against the tire-level figure.

# %%
import tempfile
from pathlib import Path

from IPython.display import Image, display

from tire_learning_env.studies import run_study, study_spec

out = Path(tempfile.mkdtemp())
rows = []
for study in (2, 3):
    metrics = run_study(study_spec(study), out / f"study{study}", baseline="ukf")
    for name, m in (("observer", metrics), ("joint UKF", metrics["baseline"])):
        rows.append((study, name, m["tire_curve_nrmse"], m["cornering_stiffness"], m["slip_rmse_deg"]))
for study, name, curve, stiff, slip in rows:
    print(f"Study {study} {name:9s} curve NRMSE front {curve['front']:.4f} rear {curve['rear']:.4f} | "
          f"stiffness error {stiff['front']['error_pct']:+.2f} % / {stiff['rear']['error_pct']:+.2f} % | "
          f"slip RMSE {slip['front']:.4f} / {slip['rear']:.4f} deg")

# %% [markdown]
# ## Figures written by the study runner (like the paper's Figs. 9-18)

# %%
for study in (2, 3):
    for fig in ("tire_curves", "slip_angles", "force_slip_loop"):
        display(Image(filename=str(out / f"study{study}" / f"{fig}.png")))
