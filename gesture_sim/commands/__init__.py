"""Subcommands of ``gesture-sim``; each module exposes ``register(subparsers)``."""

from typing import Any


def print_json(doc: Any) -> int:
    """Print a command's ``--json`` result on stdout and return 0 (its exit status).

    ``doc`` goes through :func:`gesture_sim.fileio.jsonable` (numpy values as numbers and lists,
    paths as strings, NaN and ±inf as ``null``, which JSON has no other spelling for); anything
    else it does not know is written as ``str()``.
    """
    import json

    from gesture_sim.fileio import jsonable

    print(json.dumps(jsonable(doc), indent=1, default=str))
    return 0
