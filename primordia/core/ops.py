"""Two namespaces of elementary functions, so one formula serves two worlds.

Kinetics, growth laws and active stresses are written once as functions of an
``ops`` argument.  ``UFL`` builds symbolic expressions for weak forms;
``NUMPY`` evaluates numbers for initial data, plots and the linear stability
analysis.  ``x`` is the spatial coordinate (a UFL ``SpatialCoordinate`` or a
tuple of arrays) and is bound with :meth:`Ops.at`.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any, Callable

import numpy as np
import ufl


@dataclass(frozen=True)
class Ops:
    exp: Callable
    tanh: Callable
    sqrt: Callable
    ln: Callable
    x: Any = None

    def at(self, x) -> "Ops":
        """The same namespace with the spatial coordinate bound to ``x``."""
        return replace(self, x=x)


UFL = Ops(exp=ufl.exp, tanh=ufl.tanh, sqrt=ufl.sqrt, ln=ufl.ln)
NUMPY = Ops(exp=np.exp, tanh=np.tanh, sqrt=np.sqrt, ln=np.log)
