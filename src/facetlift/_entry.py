"""The ``facetlift`` console script: Ctrl-C while the command line is still loading (its
imports take a few tenths of a second) exits 130 with one line, as it does later, instead of
an import traceback."""

from __future__ import annotations

import sys


def main() -> int:
    try:
        from .cli import main as cli_main

        return cli_main()  # (its own error boundary catches an interrupt once it runs)
    except KeyboardInterrupt:
        sys.stderr.write("facetlift: error: interrupted\n")
        return 130
