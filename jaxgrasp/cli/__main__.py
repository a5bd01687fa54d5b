"""``python -m jaxgrasp.cli``: the same as the ``jaxgrasp`` command."""

import sys

from jaxgrasp.cli import main

sys.exit(main())
