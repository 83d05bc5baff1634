"""Helpers shared by the stability-analysis tests."""

from primordia.physics.seed_parameters import seed_parameters


def random_parameters(rng, **fixed):
    """Admissible parameters away from Table 3.1, including the scaling constants the seed sets to 1."""
    values = {
        "m0": rng.uniform(0.3, 3), "D_m": rng.uniform(0.005, 0.1), "D_f": rng.uniform(0.05, 1),
        "D_b": rng.uniform(0.5, 2), "alpha": rng.uniform(0.5, 8), "gamma": rng.uniform(0.5, 1.5),
        "kappa_1": rng.uniform(0.01, 0.5), "kappa_2": rng.uniform(0.01, 0.5), "kappa_3": rng.uniform(0.2, 2),
        "kappa_4": rng.uniform(0.2, 2), "delta_F": rng.uniform(0.5, 2), "delta_B": rng.uniform(0.5, 2),
        "kappa_F": rng.uniform(0.5, 2), "kappa_B": rng.uniform(0.5, 2), "tau": rng.uniform(-80, 80),
        "xi_f": rng.uniform(-0.3, 0.3), "E": rng.uniform(10, 1e3), "nu": rng.uniform(0.1, 0.45),
        "C_0": rng.uniform(0.01, 0.5), "kappa": rng.uniform(0.01, 1), "eta": rng.uniform(0.5, 2),
        "alpha_BW": rng.uniform(0.1, 1), "rho": rng.uniform(0.5, 2), "zeta": rng.uniform(0.2, 2),
    }
    values.update(fixed)
    return seed_parameters(**values)
