"""``python -m facetlift``: the command line, as the ``facetlift`` script (a user found
only the script)."""

import sys

from ._entry import main

if __name__ == "__main__":
    sys.exit(main())
