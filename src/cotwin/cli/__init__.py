"""The `cotwin` command: one group (`common.main`) whose commands live in a module per family."""

from __future__ import annotations

import sys

import click

from ..diagnostics import CotwinError, Interrupted
from . import access, analysis, cachecmd, fleet, history, live, models, runs, testing, urdf  # noqa: F401 - each module registers its commands
from .common import close_failed, main, no_command_running, report

__all__ = ["main", "entry"]


def _terminate(signum, frame) -> None:
    raise KeyboardInterrupt(f"signal {signum}")


def _interrupted() -> None:
    """Exit 130 after an interrupt, deaf to another: a second Ctrl-C, or a SIGTERM (an interrupt too, see
    `entry`), during the interpreter's exit (its atexit hooks, e.g. cotwin.cosim.pythonfmu_exit's) printed
    'Exception ignored in atexit callback' and a traceback."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_IGN)
    sys.exit(130)


def entry() -> None:
    """Entry point: every error escaping a command is reported as a message, never a traceback, and a command
    that counts its errors and warnings (common.closing_tally: cotwin run, twin, build) closes with the count after it.
    SIGTERM ends a run like Ctrl-C: units are ended properly and the rows so far are kept."""
    import signal

    signal.signal(signal.SIGTERM, _terminate)
    no_command_running()
    try:
        main(standalone_mode=False)
    except CotwinError as err:
        report(err.findings)
        if isinstance(err, Interrupted):
            _interrupted()
        close_failed(err.findings)
        sys.exit(1)
    except OSError as err:  # a file or folder that cannot be read or written
        click.echo(f"error: {err.strerror or err}{f': {err.filename}' if err.filename else ''}", err=True)
        close_failed()
        sys.exit(1)
    except (click.exceptions.Abort, KeyboardInterrupt):
        click.echo("interrupted", err=True)
        _interrupted()
    except click.ClickException as err:
        err.show()
        close_failed()
        sys.exit(err.exit_code)
    except RecursionError:
        click.echo("error: the input is nested too deeply to process", err=True)
        close_failed()
        sys.exit(1)
    except Exception as err:  # noqa: BLE001 - a bug of cotwin's: say so in one line, keep the details
        import tempfile
        import traceback

        with tempfile.NamedTemporaryFile("w", prefix="cotwin-crash-", suffix=".txt", delete=False) as f:
            traceback.print_exc(file=f)
        click.echo(f"internal error: {type(err).__name__}: {str(err)[:300]} (a cotwin bug; details in {f.name})",
                   err=True)
        close_failed()
        sys.exit(70)
    finally:
        no_command_running()
