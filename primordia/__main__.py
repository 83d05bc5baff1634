"""``python -m primordia``: the ``primordia`` command (:mod:`primordia.cli`)."""

from primordia.cli import console

console()
