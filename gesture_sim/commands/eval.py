"""``gesture-sim eval MODE ...``: evaluations that print a table (or JSON with ``--json``).

Modes are sub-commands registered from :data:`EVAL_MODES` (module path, function name); each
adds its own parser. ``inference`` is the paper's Figure 4 (held-out likelihood per step of
the remapped CRF and of an HMM over the same input windows). Motion-quality evaluation of
rendered speech can be added as another mode without touching the existing ones.
"""

from __future__ import annotations

import argparse
import importlib

#: (module, register function) of each evaluation mode, in ``--help`` order.
EVAL_MODES = (
    ("gesture_sim.inference.cli_eval", "register"),
)


def register(sub: argparse._SubParsersAction) -> None:
    parser = sub.add_parser(
        "eval", help="evaluate models and output (e.g. `eval inference`: CRF vs HMM, Fig. 4)",
        description="Evaluations; each mode prints a table, or JSON with --json.",
    )
    modes = parser.add_subparsers(dest="eval_mode", metavar="MODE")
    for module_name, fn in EVAL_MODES:
        try:
            module = importlib.import_module(module_name)
        except ModuleNotFoundError as exc:
            if exc.name == module_name:
                continue
            raise
        getattr(module, fn)(modes)
    parser.set_defaults(func=lambda args: parser.print_help() or 1)
