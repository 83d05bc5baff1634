"""``python -m primordia``: the ``primordia`` command (:mod:`primordia.cli`)."""

import sys

from primordia.cli import main

sys.exit(main())
