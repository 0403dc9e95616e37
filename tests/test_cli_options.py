"""One meaning per option across the commands, and help a user can read."""

from __future__ import annotations

import typer.main
from typer.testing import CliRunner

from polyswarm.cli import app


def _commands(cmd=None, path=()):
    cmd = cmd or typer.main.get_command(app)
    if hasattr(cmd, "commands"):
        for name, sub in cmd.commands.items():
            yield from _commands(sub, (*path, name))
    else:
        yield path, cmd


def _options(cmd) -> dict[str, str]:
    return {o: (p.help or "") for p in cmd.params if p.param_type_name == "option" for o in p.opts}


def test_the_zenoh_address_is_connect_or_listen_everywhere():
    for path, cmd in _commands():
        opts = _options(cmd)
        assert "--endpoint" not in opts, path
        if "--connect" in opts:
            assert "connect to" in opts["--connect"].lower(), path
        if "--listen" in opts:
            assert "listen" in opts["--listen"].lower(), path


def test_every_output_option_is_out_and_says_what_it_writes():
    for path, cmd in _commands():
        opts = _options(cmd)
        if "-o" in opts:
            assert "--out" in opts, path
        for name in ("--output", "--output-dir"):
            assert name not in opts, path


def test_flags_show_no_value_in_help():
    runner = CliRunner()
    for path, _ in _commands():
        res = runner.invoke(app, [*path, "--help"], env={"COLUMNS": "120"})
        assert res.exit_code == 0, (path, res.output)
        assert "<bool>" not in res.output, path


def test_durations_say_their_clock_in_the_name():
    """--time-limit is simulated seconds, --wall-limit wall-clock seconds, everywhere."""
    for path, cmd in _commands():
        opts = _options(cmd)
        assert "--duration" not in opts, path
        if "--time-limit" in opts:
            assert "simulated" in opts["--time-limit"].lower(), path
        if "--wall-limit" in opts:
            assert "wall" in opts["--wall-limit"].lower(), path
