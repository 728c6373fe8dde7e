"""The ``cpm`` command, as the wheel installs it (``[project.scripts]``): the command-line
tool of the Rust crate, run in this process, with the same options, files and exit codes
(``docs/cli.md``)."""
from __future__ import annotations

import signal
import sys

from . import _cpm


def main() -> None:
    """Runs ``cpm`` with this process's arguments and exits with its exit code."""
    # The command's work runs without the GIL: Ctrl-C stops it as it stops the binary.
    signal.signal(signal.SIGINT, signal.SIG_DFL)
    sys.stdout.flush()
    sys.exit(_cpm.main(["cpm", *sys.argv[1:]]))


if __name__ == "__main__":
    main()
