"""Linear stability analysis of the poro-mechano-chemical model (seed section 3).

Will this parameter set pattern, at what wavelength, and what happens if tau or
xi_f change?  From Python::

    from primordia.physics.seed_parameters import seed_parameters
    from primordia.analysis import fastest_growing_mode, growth_rates, patterning_space, verdicts

    params = seed_parameters(m0=0.75)              # Table 3.1, overridden by seed name
    mode = fastest_growing_mode(params, kind="stationary")
    mode.k_max, mode.wavelength, mode.growth_rate  # Turing wavenumber, 2 pi / k_max, Re phi
    growth_rates(params, k=[0.5, 1.0, 2.0], d=3)   # every root of det M(phi, k) = 0
    for verdict in verdicts(params):               # seed sections 3.2-3.6, one line each
        print(verdict)
    ds = patterning_space(x="tau:-100:100:81", y="xi_f:-0.5:0.5:81")   # an xarray Dataset

and from the shell: ``primordia stability --help`` (see README.md here).

Modules: :mod:`.linearisation` (steady state, M(phi, k) of Definition 3.1),
:mod:`.dispersion` (growth rates by a linearised generalised eigenproblem),
:mod:`.polynomials` (closed forms P_1, P_2, P_3, theta_i; the corrections to
the seed's printed coefficients are listed in its docstring),
:mod:`.conditions` (Routh-Hurwitz, (3.3)-(3.8), critical values, verdicts),
:mod:`.patterning` (patterning spaces and dispersion curves as Datasets /
NetCDF), :mod:`.figures` (seed Figures 3.1-3.3 layout), :mod:`.inputs`,
:mod:`.cli`.
"""

from primordia.analysis.conditions import (
    Conditions,
    CriticalValue,
    Verdict,
    conditions,
    coupled_conditions,
    coupled_verdict,
    critical_value,
    critical_wavenumber,
    epithelium_verdict,
    homogeneous_verdict,
    patterning_region,
    routh_hurwitz_cubic,
    routh_hurwitz_quartic,
    uncoupled_conditions,
    uncoupled_verdict,
    verdicts,
    zero_chemotaxis_verdict,
)
from primordia.analysis.dispersion import (
    FastestMode,
    GrowthRates,
    default_wavenumbers,
    fastest_growing_mode,
    growth_rates,
    longitudinal_rates,
    max_growth_rate,
)
from primordia.analysis.inputs import read_parameters
from primordia.analysis.linearisation import (
    LinearisedCoefficients,
    dispersion_matrix,
    linearise,
    matrix_pencil,
)
from primordia.analysis.patterning import (
    ParameterRange,
    dispersion_relation,
    patterning_space,
    save_dataset,
)
from primordia.analysis.polynomials import (
    a0,
    characteristic_determinant,
    chemotaxis_coefficients,
    coupling_coefficients,
    d0,
    dispersion_coefficients,
    mechanics_coefficients,
    theta,
    transverse_coefficients,
)

__all__ = [
    "Conditions",
    "CriticalValue",
    "FastestMode",
    "GrowthRates",
    "LinearisedCoefficients",
    "ParameterRange",
    "Verdict",
    "a0",
    "characteristic_determinant",
    "chemotaxis_coefficients",
    "conditions",
    "coupled_conditions",
    "coupled_verdict",
    "coupling_coefficients",
    "critical_value",
    "critical_wavenumber",
    "d0",
    "default_wavenumbers",
    "dispersion_coefficients",
    "dispersion_matrix",
    "dispersion_relation",
    "epithelium_verdict",
    "fastest_growing_mode",
    "growth_rates",
    "homogeneous_verdict",
    "linearise",
    "longitudinal_rates",
    "matrix_pencil",
    "max_growth_rate",
    "mechanics_coefficients",
    "patterning_region",
    "patterning_space",
    "read_parameters",
    "routh_hurwitz_cubic",
    "routh_hurwitz_quartic",
    "save_dataset",
    "theta",
    "transverse_coefficients",
    "uncoupled_conditions",
    "uncoupled_verdict",
    "verdicts",
    "zero_chemotaxis_verdict",
]
