"""The ``polyswarm`` command: the composition root of the project.

Only this package wires the core, the simulator (``sim``), the agents (``agents``) and
Zenoh together; heavy imports happen inside the commands. Known errors
(``PolyswarmError``) become a one-line message and exit code 1.
"""

from __future__ import annotations

import contextlib
import faulthandler
import logging
import os
import signal
import sys
from typing import NoReturn

import typer

from polyswarm import __version__
from polyswarm.errors import PolyswarmError


def _flags_take_no_value() -> None:
    """typer 0.29 prints ``<bool>`` beside every flag in ``--help``, as if it took a
    value; a flag's help shows none."""
    from typer.core import TyperOption

    shown = TyperOption.display_type_rich

    def display_type_rich(self, ctx):
        return None if self.is_flag else shown(self, ctx)

    TyperOption.display_type_rich = display_type_rich


_flags_take_no_value()
app = typer.Typer(
    help="polyswarm: multi-robot exploration with polygon maps (PolyMap), PolySLAM and Zenoh.",
    no_args_is_help=True,
    pretty_exceptions_enable=False,
    rich_markup_mode="rich",
    context_settings={"help_option_names": ["-h", "--help"]},
)
map_app = typer.Typer(help="Convert, inspect and export PolyMaps.", no_args_is_help=True)
bench_app = typer.Typer(
    help="Benchmarks: a table by default, --json for machines.", no_args_is_help=True
)
app.add_typer(map_app, name="map")
app.add_typer(bench_app, name="bench")


def _version(value: bool) -> None:
    if value:
        typer.echo(f"polyswarm {__version__}")
        raise typer.Exit()


@app.callback()
def _root(
    version: bool = typer.Option(
        False, "--version", callback=_version, is_eager=True, help="Print the version and exit."
    ),
    verbose: int = typer.Option(
        0, "--verbose", "-v", count=True, help="More log output (-vv: debug)."
    ),
) -> None:
    level = logging.WARNING if verbose == 0 else logging.INFO if verbose == 1 else logging.DEBUG
    setup_logging(level)
    # SIGUSR1 writes every thread's stack to stderr, even while Python waits in C code:
    # `launch` sends it to a child that did not stop in time, before killing it
    with contextlib.suppress(AttributeError, ValueError, RuntimeError):  # no SIGUSR1 here
        faulthandler.register(signal.SIGUSR1, all_threads=True)


def exit_now(code: int = 0) -> NoReturn:
    """End a long-running process (agent, coordinator) once its work is saved and its
    Zenoh session closed, skipping the interpreter's teardown: its garbage collection
    over every map object outlasted `launch`'s shutdown grace on a loaded machine (ten
    agents on two cores; faulthandler showed them killed while "Garbage-collecting").

    The multiprocessing finalisers that teardown would run are run here: without them
    the queues' semaphores of the coordinator's worker processes stayed registered, and
    the resource tracker warned of "leaked semaphore objects" in every coordinator log."""
    from multiprocessing import util

    with contextlib.suppress(Exception):
        util._run_finalizers(0)  # what the interpreter's exit runs (priority >= 0)
    logging.shutdown()
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(code)


def setup_logging(level: int) -> None:
    """Log lines go to standard error, so that ``--json`` output on standard output stays
    machine-readable whatever is logged."""
    from rich.console import Console
    from rich.logging import RichHandler

    root = logging.getLogger()
    if not any(isinstance(h, RichHandler) for h in root.handlers):
        handler = RichHandler(
            console=Console(stderr=True), show_path=False, rich_tracebacks=False, markup=False
        )
        handler.setFormatter(logging.Formatter("%(name)s: %(message)s"))
        root.addHandler(handler)
    root.setLevel(level)


PROFILE_HELP = (
    "Robot profile: thesis, turtlebot3, turtlebot4, hokuyo or thesis-noisy-odometry (its "
    "lidar, base and odometry noise; values the config file sets win). Default: the "
    "config's, else thesis."
)


def load_cfg(config_path, profile: str | None = None):
    """The TOML config (or the defaults) with ``--profile`` applied."""
    from polyswarm.config import load_config, with_profile

    return with_profile(load_config(config_path), profile)


# command modules register themselves on the apps above
from polyswarm.cli import (  # noqa: E402,F401
    bench_cmds,
    bench_fleet_cmds,
    bench_map_cmds,
    bench_mission_cmds,
    map_cmds,
    sim_cmds,
    slam_cmds,
    swarm_cmds,
)


def main(argv: list[str] | None = None) -> None:
    """Entry point: typer handles usage errors and --help; our errors become one line."""
    try:
        app(args=argv)
    except PolyswarmError as e:
        logging.getLogger("polyswarm").debug("error", exc_info=True)
        typer.secho(f"error: {e}", fg=typer.colors.RED, err=True)
        sys.exit(1)
    except OSError as e:  # a file or folder that is missing, exists, or is not allowed
        logging.getLogger("polyswarm").debug("error", exc_info=True)
        where = f": {e.filename}" if e.filename else ""
        typer.secho(f"error: {e.strerror or e}{where}", fg=typer.colors.RED, err=True)
        sys.exit(1)
    except KeyboardInterrupt:
        typer.secho("interrupted", err=True)
        sys.exit(130)
