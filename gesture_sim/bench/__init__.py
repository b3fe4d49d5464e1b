"""Benchmarks behind ``gesture-sim bench``; each module exposes ``register(subparsers)``."""
