"""Finding a test's child processes by an environment tag (Linux ``/proc``), for tests that
check a signal leaves no worker or ffmpeg behind."""

from __future__ import annotations

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
