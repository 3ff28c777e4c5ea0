"""The ``bsdfit`` command that ``pip install`` puts on the PATH: the command line, run
whole through the native module (the same code as the binary ``cargo build`` makes)."""

from __future__ import annotations

import signal
import sys

from . import _bsdfit


def main() -> None:
    """Run ``bsdfit`` with this process's arguments and exit with its status."""
    # The command behaves as the binary does: Ctrl-C stops it at once (Python would only
    # note the signal until the native call returns), and `bsdfit models | head` ends
    # quietly when the pipe closes.
    signal.signal(signal.SIGINT, signal.SIG_DFL)
    if hasattr(signal, "SIGPIPE"):
        signal.signal(signal.SIGPIPE, signal.SIG_DFL)
    sys.exit(_bsdfit.run_cli(["bsdfit", *sys.argv[1:]]))


if __name__ == "__main__":
    main()
