"""What the model fits went through, counted instead of printed.

hmmlearn reports every EM iteration whose likelihood went down ("Model is not converging") on
its logger, and scikit-learn's k-means warns when it finds fewer distinct clusters than asked
(``ConvergenceWarning``); a state-count sweep makes dozens of such lines. The fitting code
(:func:`gesture_sim.inference.hmm.fit_hmm`) captures them at the source and reports each fit to
every :class:`FitLog` that is collecting (:func:`collect`), so a command can print one line
such as ``EM did not converge in 3 of 40 fits`` at the end (:meth:`FitLog.summary`).

Only the standard library is imported here (the command line imports this module).
"""

from __future__ import annotations

import contextlib
import contextvars
from collections import Counter
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field


@dataclass
class FitLog:
    """Counts over the EM fits reported while it collected.

    Attributes:
        fits: EM runs started (one per restart).
        not_converged: runs that stopped at the iteration limit or whose likelihood went down
            in some iteration (hmmlearn's "Model is not converging").
        likelihood_drops: iterations, over all runs, whose likelihood went down.
        failed: runs that raised (degenerate covariance, ...) and were skipped.
        warnings: short texts of the library warnings caught, with the number of fits that
            raised each.
    """

    fits: int = 0
    not_converged: int = 0
    likelihood_drops: int = 0
    failed: int = 0
    warnings: Counter = field(default_factory=Counter)

    def add_fit(self, converged: bool, drops: int = 0, failed: bool = False,
                warnings: Iterable[str] = ()) -> None:
        """Count one EM run (see :func:`record_fit`)."""
        self.fits += 1
        self.failed += int(failed)
        self.not_converged += int(not failed and not converged)
        self.likelihood_drops += int(drops)
        self.warnings.update(set(warnings))

    def to_dict(self) -> dict:
        """JSON-ready counts."""
        return {"fits": self.fits, "not_converged": self.not_converged,
                "likelihood_drops": self.likelihood_drops, "failed": self.failed,
                "warnings": dict(self.warnings)}

    def summary(self) -> str | None:
        """One line about what went wrong, or ``None`` when every fit converged cleanly."""
        parts = []
        if self.not_converged:
            parts.append(f"EM did not converge in {self.not_converged} of {self.fits} fits")
        if self.failed:
            parts.append(f"EM failed in {self.failed} of {self.fits} fits (skipped)")
        for text, count in sorted(self.warnings.items()):
            parts.append(f"{text} in {count} of {self.fits} fits")
        if not parts:
            return None
        return "; ".join(parts) + " (the best restart of each fit is kept)"


_ACTIVE: contextvars.ContextVar[tuple[FitLog, ...]] = contextvars.ContextVar(
    "gesture_sim_fit_logs", default=())


@contextlib.contextmanager
def collect() -> Iterator[FitLog]:
    """Collect the fits reported inside the ``with`` block (nested collectors all count)."""
    log = FitLog()
    token = _ACTIVE.set((*_ACTIVE.get(), log))
    try:
        yield log
    finally:
        _ACTIVE.reset(token)


def record_fit(converged: bool, drops: int = 0, failed: bool = False,
               warnings: Iterable[str] = ()) -> None:
    """Report one EM run to every active collector (no-op when none collects).

    Args:
        converged: EM met its tolerance before the iteration limit, likelihood never falling.
        drops: iterations whose likelihood went down.
        failed: the run raised and was skipped.
        warnings: short texts of library warnings caught during the run.
    """
    texts = list(warnings)
    for log in _ACTIVE.get():
        log.add_fit(converged, drops, failed, texts)
