"""``python -m studies.cli``: the ``flexvib`` command."""

import sys

from . import main

sys.exit(main())
