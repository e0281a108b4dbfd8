"""`python -m roachplan ...` works like the `roachplan` command."""

import sys

from roachplan.app.cli import main

sys.exit(main())
