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
# # 4. The discrepancy workflow on a log with a hidden effect
#
# We make a log in the shared format from the truth vehicle with a tire relaxation length
# of 0.5 m hidden in it (the bicycle model has none), with a 20 Hz camera and +/-1 cm /
# +/-0.1 deg noise. The workflow sees only the log's measured columns and a nominal model
# (bicycle + Pacejka tire), and must say which effect is missing and how big it is.

# %%
import tempfile
from pathlib import Path

from IPython.display import Image, display

from tire_learning_env.discrepancy import EFFECT_NAMES, analyze, write_report
from tire_learning_env.discrepancy.truth import simulate_hidden
from tire_learning_env.io import read_log, write_log

print("effect library:", EFFECT_NAMES)
work = Path(tempfile.mkdtemp())
columns = simulate_hidden({"tire_relaxation": 0.5}, road="identification", duration=60.0, camera_rate=20.0, seed=1)
write_log(work / "hidden.csv", columns)
log = read_log(work / "hidden.csv")  # true_* columns are kept apart in log.truth and never read

# %% [markdown]
# ## Compare, locate, name, add

# %%
result = analyze(log, tire="pacejka", progress=False)
report = result.to_json()
print("verdict:", report["verdict"])
for effect in report["effects"]:
    print(effect["name"], effect["parameters"], effect["units"])
print("gap before:", report["gap_before"])
print("gap after:", report["gap_after"])
print("gap ratio:", report["gap_ratio"])

# %% [markdown]
# ## The report and its figures (written atomically)

# %%
out = write_report(result, work / "report")
for png in sorted(out.glob("*.png")):
    print(png.name)
    display(Image(filename=str(png)))
