"""Save an episode of a tire-learning env (e.g. a highway-env scene) as an animated GIF (headless).

Frames come from the environment's ``render()`` (highway-env's renderer, drawn offscreen:
no display needed) and are written with Pillow, one frame per policy step, played at the
policy rate (:func:`tire_learning_env.rendering.record_episode`).

Command line::

    python examples/record_episode.py --env TireLearning-Highway-v0 \\
        --seconds 20 --seed 0 --out highway.gif --config '{"vehicles_count": 30}'
"""

from __future__ import annotations

import argparse
import json


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--env", default="TireLearning-Highway-v0", help="registered id")
    parser.add_argument("--out", default="episode.gif", help="output GIF")
    parser.add_argument("--seconds", type=float, default=20.0, help="simulated time [s]")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--every", type=int, default=1, help="keep one frame every N policy steps")
    parser.add_argument("--config", default=None, help="JSON dict of env config keys")
    args = parser.parse_args(argv)
    import tire_learning_env  # noqa: F401  (registers the ids)
    from tire_learning_env.rendering import record_episode

    config = json.loads(args.config) if args.config else None
    result = record_episode(args.env, args.out, args.seconds, args.seed, every=args.every, config=config)
    print(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
