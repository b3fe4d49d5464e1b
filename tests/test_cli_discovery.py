"""Command discovery: every listed command is registered; a broken one is an error."""

from __future__ import annotations

import importlib
import pkgutil

import pytest

import gesture_sim.commands
from gesture_sim import cli


def test_every_command_module_is_listed_in_help() -> None:
    parser = cli.build_parser()
    sub = next(a for a in parser._actions if a.dest == "command")
    assert set(cli.COMMAND_MODULES) <= set(sub.choices)


def test_every_module_under_commands_imports() -> None:
    names = [m.name for m in pkgutil.iter_modules(gesture_sim.commands.__path__)]
    assert set(cli.COMMAND_MODULES) <= set(names)
    for name in names:
        importlib.import_module(f"gesture_sim.commands.{name}")


def test_a_command_that_fails_to_import_is_an_error(monkeypatch) -> None:
    monkeypatch.setattr(cli, "COMMAND_MODULES", (*cli.COMMAND_MODULES, "no_such_command"))
    with pytest.raises(ModuleNotFoundError, match="no_such_command"):
        cli.build_parser()
