"""Shared fixtures for the audio tests: the shipped speech WAVs (tests/data/audio)."""

from __future__ import annotations

from pathlib import Path

import pytest

DATA = Path(__file__).resolve().parents[1] / "data" / "audio"
JFK = DATA / "jfk.wav"
ARCTIC = DATA / "arctic_a0007.wav"
BEAT2 = DATA / "beat2_scott_0_2_2_excerpt.wav"


@pytest.fixture(scope="session")
def jfk_analysis():
    """Whole-file analysis of the JFK clip (computed once per session)."""
    from gesture_sim.audio.prosody import analyze_file

    return analyze_file(JFK)
