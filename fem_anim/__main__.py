"""``python -m fem_anim`` is ``fem-anim``."""

import sys

from fem_anim.cli import main

sys.exit(main())
