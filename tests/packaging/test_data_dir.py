"""The rule that finds the humanoid, the example speech and the default library."""

from __future__ import annotations

from pathlib import Path

import gesture_sim
from gesture_sim import find_data_dir


def test_a_checkout_uses_the_tree_beside_the_package() -> None:
    assert not (gesture_sim.PACKAGE_DIR / "_data").exists()   # only wheels carry it
    assert gesture_sim.DATA_DIR == gesture_sim.REPO_DIR
    assert (gesture_sim.MJCF_DIR / "humanoid.xml").is_file()
    assert (gesture_sim.DEFAULT_LIBRARY_DIR / "manifest.json").is_file()
    assert gesture_sim.EXAMPLE_SPEECH.is_file()


def test_bundled_data_win_when_present(tmp_path: Path) -> None:
    package = tmp_path / "site-packages" / "gesture_sim"
    package.mkdir(parents=True)
    assert find_data_dir(package) == tmp_path / "site-packages"    # nothing bundled: fallback
    (package / "_data" / "assets" / "mjcf").mkdir(parents=True)
    assert find_data_dir(package) == package / "_data"


def test_the_simulator_and_the_commands_use_the_rule() -> None:
    from gesture_sim.commands import demo
    from gesture_sim.sim import humanoid

    assert humanoid.HUMANOID_XML == gesture_sim.MJCF_DIR / "humanoid.xml"
    assert demo.EXAMPLE_SPEECH == gesture_sim.EXAMPLE_SPEECH
