"""The ``facetlift`` console script: Ctrl-C while the command line is still loading (its
imports take a few tenths of a second) exits 130 with one line, as it does later, instead of
an import traceback."""

from __future__ import annotations

import os
import sys
import time


def main() -> int:
    try:
        pause = os.environ.get("FACETLIFT_TEST_LOADING_MARK")
        if pause:  # (tests: say "loading" in this file, then load slowly, to be interrupted)
            with open(pause, "w") as fh:
                fh.write("loading")
            time.sleep(5.0)
        from .cli import main as cli_main

        return cli_main()  # (its own error boundary catches an interrupt once it runs)
    except KeyboardInterrupt:
        sys.stderr.write("facetlift: error: interrupted\n")
        if "--json" in sys.argv[1:]:  # (as the command line's own boundary does)
            sys.stdout.write('{"status": "interrupted", "exit_code": 130, '
                             '"error": "interrupted"}\n')
        return 130
