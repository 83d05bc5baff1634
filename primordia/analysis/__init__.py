"""Linear stability analysis of a composed model (seed section 3, generalised).

Will this model pattern, at what wavelength, and what happens if tau or xi_f
change?  The analysis of the model a configuration runs, derived from its own
equations (:mod:`.composed`)::

    from primordia import Model
    from primordia.analysis import linearise_model

    linear = linearise_model(Model.from_file("examples/ex01a.toml"))
    linear.steady_state                            # from the kinetics (seed eq. (2.6) here)
    mode = linear.fastest_mode(kind="stationary")  # k_max, wavelength 2 pi / k_max, growth_rate
    linear.growth_rates(k=[0.5, 1.0, 2.0], d=3)    # every root of det M(phi, k) = 0

and the seed's analysis typed in by hand, for parameter sets of its model (the
cross-check of the derived one, and what draws the seed's figures)::

    from primordia.physics.seed_parameters import seed_parameters
    from primordia.analysis import fastest_growing_mode, patterning_space, verdicts

    params = seed_parameters(m0=0.75)              # Table 3.1, overridden by seed name
    mode = fastest_growing_mode(params, kind="stationary")
    for verdict in verdicts(params):               # seed sections 3.2-3.6, one line each
        print(verdict)
    ds = patterning_space(x="tau:-100:100:81", y="xi_f:-0.5:0.5:81")   # an xarray Dataset

and from the shell: ``primordia stability --help`` (see README.md here).

Modules: :mod:`.composed` (the derived analysis of a Model), :mod:`.autodiff`
(dual numbers for the kinetics' Jacobian), :mod:`.linearisation` (the seed's
steady state and M(phi, k) of Definition 3.1, by hand), :mod:`.dispersion`
(growth rates by a linearised generalised eigenproblem), :mod:`.polynomials`
(closed forms P_1, P_2, P_3, theta_i; the corrections to the seed's printed
coefficients are listed in its docstring), :mod:`.conditions` (Routh-Hurwitz,
the seed's conditions, critical values, verdicts), :mod:`.patterning`
(patterning spaces and dispersion curves as Datasets / NetCDF), :mod:`.figures`
(seed Figures 3.1-3.3 layout), :mod:`.inputs`, :mod:`.cli`.
"""

from __future__ import annotations

import importlib

# Public names and the module defining each.  They are imported on first use
# (PEP 562), so ``primordia.analysis.cli`` - which the main CLI imports to build
# its parser - does not pull in scipy, xarray and matplotlib for every command.
_EXPORTS = {
    "composed": (
        "LinearisedModel", "SteadyState", "homogeneous_steady_state", "linearise_composition", "linearise_model",
        "linearise_seed", "reaction_jacobian", "seed_cross_check",
    ),
    "conditions": (
        "Conditions", "CriticalValue", "Verdict", "coupled_conditions", "coupled_verdict",
        "critical_value", "critical_wavenumber", "epithelium_verdict", "homogeneous_verdict", "instability_conditions",
        "patterning_region", "routh_hurwitz_cubic", "routh_hurwitz_quartic", "uncoupled_conditions",
        "uncoupled_verdict", "verdicts", "zero_chemotaxis_verdict",
    ),
    "dispersion": (
        "FastestMode", "GrowthRates", "default_wavenumbers", "fastest_growing_mode", "growth_rates",
        "longitudinal_rates", "max_growth_rate",
    ),
    "inputs": ("read_model", "read_parameters"),
    "linearisation": ("LinearisedCoefficients", "dispersion_matrix", "linearise", "matrix_pencil"),
    "patterning": ("ParameterRange", "dispersion_relation", "model_dispersion_relation", "patterning_space",
                   "save_dataset"),
    "polynomials": (
        "a0", "characteristic_determinant", "chemotaxis_coefficients", "coupling_coefficients", "d0",
        "dispersion_coefficients", "mechanics_coefficients", "theta", "transverse_coefficients",
    ),
    "figures": ("dispersion_figure", "patterning_figure"),
}
_MODULE_OF = {name: module for module, names in _EXPORTS.items() for name in names}
__all__ = sorted(_MODULE_OF)


def __getattr__(name: str):
    try:
        module = _MODULE_OF[name]
    except KeyError:
        raise AttributeError(f"module 'primordia.analysis' has no attribute {name!r}") from None
    value = getattr(importlib.import_module(f"primordia.analysis.{module}"), name)
    globals()[name] = value
    return value


def __dir__():
    return sorted(set(globals()) | set(__all__))
