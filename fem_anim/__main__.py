"""``python -m fem_anim`` is ``fem-anim``."""

import sys

from .cli import main

sys.exit(main())
