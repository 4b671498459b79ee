#!/usr/bin/env python
"""Where and how a policy reaches its largest lateral acceleration in one excitation episode.

    python agents/inspect_ay_peak.py                      # committed PPO policy, seed 1000
    python agents/inspect_ay_peak.py --policy runs/x.zip --seed 1003 --context 5
    git show 10bb6d7:agents/policies/ppo_excitation.zip > /tmp/ppo_penalty_only.zip
    python agents/inspect_ay_peak.py --policy /tmp/ppo_penalty_only.zip --no-filter   # the previous policy's 4.14 m/s^2

Prints JSON: the policy step with the largest IMU ``|a_y|`` (index, time, value), the
seed's truth draw, and the steps around it (normalised action, steering offset [rad],
offset the safety filter applied, max ``|a_y|`` of the step [m/s^2]). Used for the a_y
analysis in ``docs/excitation.md``.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

import numpy as np  # noqa: E402

from _common import AGENTS_DIR, load_model, model_policy  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--policy", type=Path, default=AGENTS_DIR / "policies" / "ppo_excitation.zip")
    ap.add_argument("--seed", type=int, default=1000)
    ap.add_argument("--duration", type=float, default=60.0, help="episode length [s]")
    ap.add_argument("--context", type=int, default=8, help="steps shown before the peak (3 after)")
    ap.add_argument("--no-filter", action="store_true", help="drive without the env's safety filter")
    args = ap.parse_args()

    from tire_learning_env.wrappers.excitation import ExcitationConfig, make_excitation_env

    env = make_excitation_env(config=ExcitationConfig(safety_filter=not args.no_filter))
    act = model_policy(load_model(args.policy))
    obs, _ = env.reset(seed=args.seed)
    rows = []
    for k in range(int(round(args.duration * env.unwrapped.policy_rate))):
        action = act(obs, k)
        obs, _, terminated, truncated, info = env.step(action)
        ex = info["excitation"]
        rows.append((float(np.asarray(action).reshape(-1)[0]), ex["offset"], ex["max_abs_ay"], ex["offset_requested"]))
        if terminated or truncated:
            break
    ay = np.array([r[2] for r in rows])
    peak = int(np.argmax(ay))
    dt = 1.0 / env.unwrapped.policy_rate
    window = range(max(0, peak - args.context), min(len(rows), peak + 4))
    print(json.dumps({
        "policy": str(args.policy), "seed": args.seed, "ay_limit": env.config.ay_limit,
        "safety_filter": env.config.safety_filter,
        "truth_draw": env.episode_metrics().get("truth_draw"),
        "peak": {"step": peak, "t_end_s": round((peak + 1) * dt, 3), "max_abs_ay": round(float(ay[peak]), 3)},
        "steps_over_limit": int(np.sum(ay > env.config.ay_limit)),
        "around_peak": [{"step": k, "action": round(rows[k][0], 4), "offset_requested_rad": round(rows[k][3], 5),
                         "offset_rad": round(rows[k][1], 5), "max_abs_ay": round(rows[k][2], 3)} for k in window],
    }, indent=2))  # fmt: skip


if __name__ == "__main__":
    main()
