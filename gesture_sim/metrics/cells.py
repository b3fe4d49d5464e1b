"""The per-file coupling cells: does a method beat each baseline on each file, by more than the
seed spread?

``eval motion``'s verdict (:func:`gesture_sim.metrics.summary.coupling_verdicts`) judges a
method on the means over all files. A *cell* is one (file, decisive figure) pair judged on that
file's rows alone: the method's margin over each baseline against the larger seed spread of the
pair, passed when every margin exceeds its spread. The sweeps of ``tools/sweep.py`` print them
(``--cells``), and ``tools/sweep.py --report REPORT.json`` applies them to a saved
``eval motion --report`` for all its seeds and for blocks of seeds.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from gesture_sim.metrics.summary import DECISIVE_KEYS, coupling_verdicts, summarise_rows

#: The baselines a cell compares with.
BASELINES = ("random", "mismatched")


@dataclass(frozen=True)
class Cells:
    """Per-file cells of one method.

    Attributes:
        passed, total: comparisons (file × figure × baseline) passed, and their number.
        cells_passed: (file × figure) cells where every baseline is beaten.
        lines: one markdown table row per file: ``| file | mean: +margin [spread] ✓ / ... |``.
    """

    passed: int
    total: int
    cells_passed: int
    lines: tuple[str, ...]

    @property
    def cells(self) -> int:
        """How many (file × figure) cells there are."""
        return self.total // max(len(BASELINES), 1)


def file_cells(rows: Sequence[dict], method: str = "controller",
               baselines: Sequence[str] = BASELINES,
               keys: Sequence[str] = DECISIVE_KEYS) -> Cells:
    """The cells of ``method`` on ``keys`` for each file of ``rows`` (the rows of
    :class:`gesture_sim.app.evaluation.EvalResult` or of a saved report: dicts with ``audio``,
    ``method``, ``seed`` and ``metrics``); each file judged on its own rows."""
    passed = total = cells_ok = 0
    lines = []
    methods = (method, *baselines)
    for audio in sorted({r["audio"] for r in rows}):
        summary = summarise_rows([r for r in rows if r["audio"] == audio], methods)
        figures = coupling_verdicts(summary, tuple(baselines))[method]["figures"]
        parts_all = []
        for key in keys:
            row = figures[key]
            parts = []
            for b in baselines:
                passed += bool(row[f"beats_{b}"])
                total += 1
                parts.append(f"{row[f'margin_{b}']:+.3f} [{row[f'spread_{b}']:.3f}] "
                             f"{'✓' if row[f'beats_{b}'] else '✗'}")
            cells_ok += bool(row["beats_all"])
            parts_all.append(f"{summary[method][key]['mean']:.3f}: " + " / ".join(parts))
        lines.append(f"| {audio} | " + " | ".join(parts_all) + " |")
    return Cells(passed, total, cells_ok, tuple(lines))
