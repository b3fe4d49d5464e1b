"""Finding a test's child processes by an environment tag (Linux ``/proc``), for tests that
check a signal leaves no worker or ffmpeg behind."""

from __future__ import annotations

import shutil
import subprocess
import time
from pathlib import Path


def tagged_processes(var: str, tag: str) -> dict[int, str]:
    """pid -> command line of every live (not zombie) process whose environment holds
    ``var=tag``; processes that vanish or cannot be read are skipped."""
    found = {}
    needle = f"{var}={tag}".encode()
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            if needle not in (entry / "environ").read_bytes().split(b"\0"):
                continue
            stat = (entry / "stat").read_text()
            if stat.rsplit(")", 1)[1].split()[0] == "Z":  # a zombie holds no resources
                continue
            cmd = (entry / "cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
        except OSError:
            continue
        found[int(entry.name)] = cmd
    return found


def start_xvfb(displays: range = range(90, 140)) -> tuple[subprocess.Popen, str] | None:
    """Start a virtual X server (Xvfb, 1280×720×24, black root) on the first free display
    number of ``displays``; ``(process, ":N")``, or None when Xvfb is missing or none started.
    The caller kills the process."""
    xvfb = shutil.which("Xvfb")
    if xvfb is None:
        return None
    for n in displays:
        if Path(f"/tmp/.X11-unix/X{n}").exists() or Path(f"/tmp/.X{n}-lock").exists():
            continue
        # -br: a black root window, so that a window not drawn yet is black, not a pattern
        proc = subprocess.Popen([xvfb, f":{n}", "-screen", "0", "1280x720x24", "-br",
                                 "-nolisten", "tcp"], stdout=subprocess.DEVNULL,
                                stderr=subprocess.DEVNULL)
        for _ in range(50):
            if Path(f"/tmp/.X11-unix/X{n}").exists():
                return proc, f":{n}"
            if proc.poll() is not None:
                break
            time.sleep(0.1)
        proc.kill()
    return None
