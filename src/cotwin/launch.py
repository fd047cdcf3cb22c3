"""The `cotwin` command's first code: an interrupt while cotwin's modules are still being imported (the first
few tenths of a second of any command) ends it as every other interrupt does, with one line and exit 130,
not with a traceback through the import machinery."""

from __future__ import annotations

import sys


def main() -> None:
    """The `cotwin` command (and `python -m cotwin`): cotwin.cli.entry, once its modules are imported."""
    try:
        from .cli import entry
    except KeyboardInterrupt:
        import signal

        sys.stderr.write("interrupted\n")
        signal.signal(signal.SIGINT, signal.SIG_IGN)  # deaf to another during the exit (as cotwin.cli's)
        sys.exit(130)
    entry()
