"""Subcommands of ``tire-learning``; each module defines ``register(subparsers)``."""
