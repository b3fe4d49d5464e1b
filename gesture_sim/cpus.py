"""CPU shares: how many CPUs this process may use, and how many rasteriser threads software
OpenGL (Mesa's llvmpipe, used where there is no GPU: Xvfb, EGL on a server) may start."""

from __future__ import annotations

import os


def usable_cpus() -> int:
    """CPUs this process may run on (its affinity mask where the OS has one), at least 1."""
    if hasattr(os, "sched_getaffinity"):
        return max(len(os.sched_getaffinity(0)), 1)
    return os.cpu_count() or 1


def software_gl_threads(cpus: int) -> str:
    """``LP_NUM_THREADS`` for a GL context that may use ``cpus`` CPUs: that many rasteriser
    threads, or ``"0"`` (rasterise in the drawing thread itself) for one CPU or less."""
    return str(cpus if cpus > 1 else 0)


def leave_a_cpu_for_physics() -> None:
    """Cap software GL at all usable CPUs but one (unless ``LP_NUM_THREADS`` is already set),
    before the live viewer creates its GL context.

    llvmpipe starts one rasteriser thread per CPU by default, and the passive viewer's render
    thread draws as fast as it can, so on a machine without a GPU the drawing competed with the
    physics loop for every core: on 2 cores under Xvfb a 90 s live run had frame time p95 25.5
    ms, jitter 5.5 ms and loop work 6.0 ms per frame, and with one rasteriser thread 18.1 ms,
    1.4 ms and 3.5 ms. A hardware GL driver ignores the variable.
    """
    os.environ.setdefault("LP_NUM_THREADS", str(max(usable_cpus() - 1, 1)))
