"""``python -m fbs``: the same as the ``fbs`` console script."""

import sys

from fbs.entry import main

sys.exit(main())
