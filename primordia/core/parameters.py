"""Model parameters: declared by the module that uses them, validated once.

Every physics module, kinetics plugin and growth law declares the parameters it
reads as a tuple of :class:`Parameter` (seed name, default, meaning, sign
constraint, where the default comes from).  A model collects the declarations
of its modules into one :class:`ParameterSet`; user overrides (from a TOML
``[parameters]`` table, ``--set parameters.NAME=VALUE`` or Python keywords) are
checked against those declarations, so a misspelt or unknown name, or a value
of the wrong sign, is reported in one line naming it.

Names are the seed's (Table 3.1): ``D_m``, ``kappa_1``, ``omega_3``, ``xi_f``...
All quantities are in the dimensionless form of seed section 2 unless a
declaration says otherwise.
"""

from __future__ import annotations

import difflib
from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass

from primordia.core.errors import ConfigError
from primordia.core.validation import number

#: Sign constraints a parameter can carry, with the phrase used in messages.
CONSTRAINTS = {
    "positive": ("must be > 0", lambda v: v > 0),
    "nonnegative": ("must be >= 0", lambda v: v >= 0),
    "any": ("", lambda v: True),
    "poisson": ("must lie in (-1, 0.5)", lambda v: -1.0 < v < 0.5),
}


@dataclass(frozen=True)
class Parameter:
    """One named model constant.

    ``constraint`` is one of :data:`CONSTRAINTS`; ``source`` says where the
    default comes from (e.g. ``"seed Table 3.1"``).
    """

    name: str
    default: float
    description: str
    constraint: str = "positive"
    source: str = "seed Table 3.1"

    def __post_init__(self):
        if self.constraint not in CONSTRAINTS:
            raise ValueError(f"parameter {self.name}: unknown constraint {self.constraint!r}")

    def check(self, value) -> float:
        """Return ``value`` as a float, or raise a one-line :class:`ConfigError`."""
        value = float(number(value, f"parameter {self.name}"))
        phrase, ok = CONSTRAINTS[self.constraint]
        if not ok(value):
            raise ConfigError(f"parameter {self.name} {phrase} ({self.description}), got {value:g}")
        return value


class ParameterSet(Mapping):
    """Validated values of a set of declared parameters (read-only mapping).

    >>> ps = ParameterSet([Parameter("D_m", 0.01, "cell diffusivity")], {"D_m": 0.03})
    >>> ps["D_m"]
    0.03
    """

    def __init__(self, declarations: Iterable[Parameter], overrides: Mapping[str, float] | None = None):
        self._declared: dict[str, Parameter] = {}
        for decl in declarations:
            known = self._declared.get(decl.name)
            if known is not None and known.default != decl.default:
                raise ValueError(
                    f"parameter {decl.name} declared twice with different defaults "
                    f"({known.default} and {decl.default})"
                )
            self._declared[decl.name] = decl
        self._values = {name: decl.default for name, decl in self._declared.items()}
        for name, value in (overrides or {}).items():
            self._values[name] = self.declaration(name).check(value)

    def declaration(self, name: str) -> Parameter:
        """The declaration of ``name``; an unknown name raises with suggestions."""
        try:
            return self._declared[name]
        except KeyError:
            close = difflib.get_close_matches(name, self._declared, n=3)
            hint = f" (did you mean {', '.join(close)}?)" if close else ""
            raise ConfigError(f"unknown parameter '{name}'{hint}") from None

    def replace(self, **overrides: float) -> "ParameterSet":
        """A copy with some values changed (validated like any override)."""
        merged = dict(self._values)
        merged.update(overrides)
        return ParameterSet(self._declared.values(), merged)

    def declarations(self) -> tuple[Parameter, ...]:
        return tuple(self._declared.values())

    def __getitem__(self, name: str) -> float:
        if name not in self._values:
            self.declaration(name)  # raises the one-line error
        return self._values[name]

    def __getattr__(self, name: str) -> float:
        # attribute access reads like the maths: params.D_m
        if name.startswith("_"):
            raise AttributeError(name)
        try:
            return self._values[name]
        except KeyError:
            raise AttributeError(f"no parameter named {name!r}") from None

    def __setattr__(self, name: str, value) -> None:
        # read-only: params.m0 = 1.0 made an attribute that params.m0 read back, while params["m0"], the run,
        # its config.toml and the linear analysis kept the value the model was built with
        if not name.startswith("_"):
            raise AttributeError(f"parameters are read-only: to change {name}, build a new Model with "
                                 f"parameters=model.parameters.replace({name}=...)")
        super().__setattr__(name, value)

    def __iter__(self) -> Iterator[str]:
        return iter(self._values)

    def __len__(self) -> int:
        return len(self._values)

    def __repr__(self) -> str:
        body = ", ".join(f"{k}={v:g}" for k, v in self._values.items())
        return f"ParameterSet({body})"
