"""Subcommands of ``gesture-sim``; each module exposes ``register(subparsers)``."""
