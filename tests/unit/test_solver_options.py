"""Solver settings: nested ``[solver.NAME]`` tables, who overrides whom, and one clear line for a mistake."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
from petsc4py import PETSc

from primordia.core.errors import ConfigError
from primordia.coupling.solver_options import (
    GATHER, _try_type, check_tables, check_types, check_used, check_values, combine, flatten, option_text, parallel_safe)
from primordia.coupling.solvers import write_options

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"


# -- nested tables -----------------------------------------------------------------------------
def test_nested_tables_are_option_prefixes_as_in_firedrake():
    table = {"ksp_type": "gmres", "pc_type": "fieldsplit", "splits": [["u"], ["psi", "p"]],
             "fieldsplit_u": {"ksp_type": "preonly", "pc_type": "gamg", "mg_levels": {"ksp_max_it": 2}},
             "-snes_monitor": True}
    assert flatten(table, "solver.x") == {
        "ksp_type": "gmres", "pc_type": "fieldsplit", "splits": (("u",), ("psi", "p")),
        "fieldsplit_u_ksp_type": "preonly", "fieldsplit_u_pc_type": "gamg", "fieldsplit_u_mg_levels_ksp_max_it": 2,
        "snes_monitor": ""}
    assert option_text(True) == "true" and option_text(1e-2) == "0.01"


def test_true_gives_a_viewer_option_bare_and_false_leaves_it_out():
    # PETSc reads "-ksp_monitor true" as a viewer named "true" and stopped the first solve: "Unsupported viewer true"
    table = {"ksp_monitor": True, "ksp_converged_reason": False, "snes_mf_operator": False,
             "ksp_monitor_cancel": True, "fieldsplit_u": {"ksp_view": True, "ksp_monitor_true_residual": False},
             "snes_linesearch_monitor": True, "ksp_initial_guess_nonzero": True, "ksp_monitor_short": "stdout"}
    assert flatten(table, "solver.x") == {
        "ksp_monitor": "", "snes_mf_operator": False, "ksp_monitor_cancel": True, "fieldsplit_u_ksp_view": "",
        "snes_linesearch_monitor": "", "ksp_initial_guess_nonzero": True, "ksp_monitor_short": "stdout"}


def test_true_gives_bare_every_option_named_a_monitor_or_view_not_only_after_ksp_or_snes():
    # snes_test_jacobian_view, mat_factor_view, snes_fas_monitor and ksp_lsqr_monitor are viewers too: "true"
    # reached PETSc and stopped the run; a ksp_gmres_krylov_monitor PETSc asks only for presence: "false" was on
    table = {"snes_test_jacobian_view": True, "sub": {"mat_factor_view": True}, "snes_fas_monitor": True,
             "ksp_lsqr_monitor": True, "ksp_gmres_krylov_monitor": False, "pc_gasm_view_subdomains": True,
             "snes_converged_reason_view_cancel": True, "snes_test_jacobian": 1e-8, "snes_monitor_pause_final": False}
    assert flatten(table, "solver.x") == {
        "snes_test_jacobian_view": "", "sub_mat_factor_view": "", "snes_fas_monitor": "", "ksp_lsqr_monitor": "",
        "pc_gasm_view_subdomains": "", "snes_converged_reason_view_cancel": True, "snes_test_jacobian": 1e-8,
        "snes_monitor_pause_final": False}


def test_a_jacobian_test_view_set_true_prints_the_difference(capfd, tmp_path):
    from primordia.cli import main

    status = main(["run", str(EXAMPLES / "ex02a.toml"), "--out", str(tmp_path / "out"), "--no-progress",
                   "--set", "mesh.cells=[4,4]", "--set", "time.t_final=0.2", "--set", "output.times=[0.2]",
                   "--set", "output.pictures=false", "--set", "solver.poroelastic_growth.snes_test_jacobian=1e-12",
                   "--set", "solver.poroelastic_growth.snes_test_jacobian_view=true"])
    out, err = capfd.readouterr()
    assert status == 0, err
    assert "Hand-coded minus finite-difference Jacobian" in out, out[:2000]


@pytest.mark.parametrize("table, spellings", [
    ({"sub": {"pc_type": "lu"}, "sub_pc_type": "icc"}, "sub_pc_type is given twice, as sub.pc_type and as sub_pc_type"),
    ({"fieldsplit_u_pc_type": "gamg", "fieldsplit_u": {"pc_type": "hypre"}},
     "fieldsplit_u_pc_type is given twice, as fieldsplit_u_pc_type and as fieldsplit_u.pc_type"),
    ({"fieldsplit": {"u": {"ksp_type": "cg"}}, "fieldsplit_u": {"ksp_type": "gmres"}},
     "fieldsplit_u_ksp_type is given twice, as fieldsplit.u.ksp_type and as fieldsplit_u.ksp_type"),
    ({"ksp_rtol": 1e-3, "-ksp_rtol": 1e-4}, "ksp_rtol is given twice, as ksp_rtol and as -ksp_rtol"),
])
def test_one_option_written_twice_is_named_with_both_spellings(table, spellings):
    # the one written last used to win, silently
    with pytest.raises(ConfigError, match=rf"^solver\.x: option {spellings.replace('.', r'[.]')}$"):
        flatten(table, "solver.x")


def test_option_names_are_read_in_any_case_as_petsc_reads_them():
    # a PC_TYPE that kept the defaults of the preconditioner it replaced, since combine() looked for pc_type
    table = {"PC_TYPE": "hypre", "FieldSplit_U": {"KSP_Type": "preonly"}, "Splits": [["u"]]}
    assert flatten(table, "solver.x") == {"pc_type": "hypre", "fieldsplit_u_ksp_type": "preonly", "splits": (("u",),)}
    assert combine(DEFAULTS, flatten({"PC_TYPE": "gamg"}, "solver.x")) == {"pc_type": "gamg", "snes_rtol": 1e-7,
                                                                            "ksp_rtol": 1e-8}


@pytest.mark.parametrize("table, fragment", [
    ({"ksp_rtol": [1e-2]}, "solver.x.ksp_rtol must be a number, a string or true/false"),
    ({"splits": ["u", "p"]}, "solver.x.splits must be a list of lists of field names"),
    ({"rebuild_preconditioner_after": -1}, "solver.x.rebuild_preconditioner_after must be a number of Krylov"),
    ({"rebuild_preconditioner_after": True}, "solver.x.rebuild_preconditioner_after must be a number of Krylov"),
    ({"rebuild_preconditioner_after": "+2"}, "solver.x.rebuild_preconditioner_after must be a number of Krylov"),
    ({"rebuild_preconditioner_after": "fresh+"}, "solver.x.rebuild_preconditioner_after must be a number of Krylov"),
    ({"rebuild_preconditioner_after": "-1"}, "solver.x.rebuild_preconditioner_after must be a number of Krylov"),
    ({"solve_on_one_rank": "yes"}, "solver.x.solve_on_one_rank must be true or false"),
    (3, "solver.x must be a table"),
])
def test_a_malformed_table_is_one_line(table, fragment):
    with pytest.raises(ConfigError, match=fragment.replace(".", r"\.")):
        flatten(table, "solver.x")


# -- who wins ------------------------------------------------------------------------------------
DEFAULTS = {"ksp_type": "preonly", "pc_type": "lu", "pc_factor_mat_solver_type": "mumps", "mat_mumps_icntl_14": 80,
            "snes_rtol": 1e-7, "ksp_rtol": 1e-8}


def test_user_options_override_the_defaults():
    assert combine(DEFAULTS, {"ksp_rtol": 1e-3}) == {**DEFAULTS, "ksp_rtol": 1e-3}
    assert combine(DEFAULTS, {"pc_type": "lu"}) == DEFAULTS  # the same preconditioner keeps its settings


def test_a_new_pc_type_drops_what_only_made_sense_for_the_old_one():
    combined = combine(DEFAULTS, {"pc_type": "gamg"})
    assert combined == {"pc_type": "gamg", "snes_rtol": 1e-7, "ksp_rtol": 1e-8}  # no factor package, no preonly
    assert combine(DEFAULTS, {"pc_type": "gamg", "ksp_type": "preonly"})["ksp_type"] == "preonly"  # unless asked
    # another direct solve keeps the direct solve's preonly (it was GMRES around an exact Cholesky factor)
    assert combine(DEFAULTS, {"pc_type": "cholesky"}) == {"ksp_type": "preonly", "pc_type": "cholesky",
                                                          "snes_rtol": 1e-7, "ksp_rtol": 1e-8}


def test_mumps_takes_its_own_ordering_unless_the_user_gives_one():
    """PETSc's nd handed to serial MUMPS replaces MUMPS's analysis: 18 times the fill on a 2D Laplacian."""
    direct = {"ksp_type": "preonly", "pc_type": "lu", "pc_factor_mat_ordering_type": "nd"}
    assert combine(direct, {"pc_factor_mat_solver_type": "mumps"}) == {
        "ksp_type": "preonly", "pc_type": "lu", "pc_factor_mat_solver_type": "mumps"}
    assert combine({**direct, "pc_factor_mat_solver_type": "mumps"}, {}) == {
        "ksp_type": "preonly", "pc_type": "lu", "pc_factor_mat_solver_type": "mumps"}
    assert combine(direct, {"pc_factor_mat_solver_type": "mumps", "pc_factor_mat_ordering_type": "rcm"})[
        "pc_factor_mat_ordering_type"] == "rcm"  # the user's own stays
    assert combine(direct, {"pc_factor_mat_solver_type": "superlu"})["pc_factor_mat_ordering_type"] == "nd"
    nested = {"pc_type": "bjacobi", "sub_pc_type": "lu", "sub_pc_factor_mat_ordering_type": "nd"}
    assert "sub_pc_factor_mat_ordering_type" not in combine(nested, {"sub_pc_factor_mat_solver_type": "mumps"})


def test_a_grouped_system_is_solved_directly_with_pivoting_where_a_module_needs_it():
    from primordia.coupling.splitting import MONOLITHIC_DEFAULTS, PIVOTING_DIRECT, grouped_direct

    lu = {"ksp_type": "preonly", "pc_type": "lu"}
    assert grouped_direct([lu, {"pc_type": "hypre"}]) == MONOLITHIC_DEFAULTS
    assert grouped_direct([lu, {**lu, "pc_factor_mat_solver_type": "mumps"}]) == PIVOTING_DIRECT
    assert grouped_direct([{"pc_type": "fieldsplit"}]) == PIVOTING_DIRECT
    assert "pc_factor_mat_ordering_type" not in PIVOTING_DIRECT


def test_a_relative_rebuild_rule_outlives_a_new_pc_type_and_a_count_of_iterations_does_not():
    """"fresh+K" compares a kept preconditioner with a fresh one of its own kind, so it holds for any; a count
    was chosen for the preconditioner it came with (10 GMRES iterations with a kept LU)."""
    cells = {"ksp_type": "gmres", "pc_type": "bjacobi", "rebuild_preconditioner_after": "fresh+1",
             "sub_pc_factor_mat_ordering_type": "rcm"}
    assert combine(cells, {"pc_type": "hypre"}) == {"ksp_type": "gmres", "pc_type": "hypre",
                                                    "rebuild_preconditioner_after": "fresh+1"}
    counted = {**cells, "rebuild_preconditioner_after": 10}
    assert "rebuild_preconditioner_after" not in combine(counted, {"pc_type": "hypre"})
    assert combine(counted, {"pc_type": "bjacobi"}) == counted  # the same preconditioner keeps its count


def test_a_new_pc_type_of_one_split_drops_that_split_s_settings_only():
    defaults = flatten({"pc_type": "fieldsplit", "splits": [["u"], ["p"]],
                        "fieldsplit_u": {"ksp_type": "preonly", "pc_type": "gamg", "pc_gamg_threshold": 0.02},
                        "fieldsplit_p": {"ksp_type": "preonly", "pc_type": "hypre"}}, "defaults")
    combined = combine(defaults, flatten({"fieldsplit_u": {"pc_type": "hypre"}}, "solver.x"))
    assert combined == {"pc_type": "fieldsplit", "splits": (("u",), ("p",)), "fieldsplit_u_ksp_type": "preonly",
                        "fieldsplit_u_pc_type": "hypre", "fieldsplit_p_ksp_type": "preonly",
                        "fieldsplit_p_pc_type": "hypre"}
    assert "splits" not in combine(defaults, {"pc_type": "lu"})  # a whole-matrix preconditioner: no splits


def test_a_direct_solve_gets_a_package_that_works_on_the_ranks_it_has():
    options = {"pc_type": "lu", "fieldsplit_u_pc_type": "lu", "sub_pc_type": "lu", "fieldsplit_p_redundant_pc_type": "lu"}
    assert parallel_safe(options, parallel=False)["pc_factor_mat_solver_type"] == "petsc"
    # a system gathered to one rank is solved there by a serial factorisation, and the option goes when pc_type does
    assert parallel_safe({"pc_type": "lu", GATHER: True}, parallel=True)["pc_factor_mat_solver_type"] == "petsc"
    assert GATHER not in combine({"ksp_type": "preonly", "pc_type": "lu", GATHER: True}, {"pc_type": "hypre"})
    parallel = parallel_safe(options, parallel=True)
    assert parallel["pc_factor_mat_solver_type"] == parallel["fieldsplit_u_pc_factor_mat_solver_type"] == "mumps"
    assert parallel["sub_pc_factor_mat_solver_type"] == "petsc"  # block Jacobi blocks are serial
    assert parallel["fieldsplit_p_redundant_pc_factor_mat_solver_type"] == "petsc"  # so is a redundant whole
    assert parallel_safe({"pc_type": "lu", "pc_factor_mat_solver_type": "superlu"}, True)[
        "pc_factor_mat_solver_type"] == "superlu"


# -- mistakes ----------------------------------------------------------------------------------
@pytest.mark.parametrize("options, fragment", [
    ({"pc_type": "gamgg"}, "unknown PC type 'gamgg' in pc_type (did you mean gamg"),
    ({"ksp_type": "gmress"}, "unknown KSP type 'gmress' in ksp_type (did you mean gmres"),
    ({"fieldsplit_u_pc_type": "amg"}, "unknown PC type 'amg' in fieldsplit_u_pc_type"),
    ({"snes_type": "newton"}, "unknown SNES type 'newton'"),
    ({"pc_factor_mat_solver_type": "pardiso"}, "factor package 'pardiso' in pc_factor_mat_solver_type"),
])
def test_unknown_types_are_named(options, fragment):
    with pytest.raises(ConfigError) as error:
        check_types(options, "solver.x")
    assert str(error.value).startswith("solver.x: ") and fragment in str(error.value)
    assert "\n" not in str(error.value)


def test_known_types_pass():
    check_types({"ksp_type": "gmres", "pc_type": "hypre", "fieldsplit_u_pc_type": "gamg", "snes_type": "newtonls",
                 "pc_factor_mat_solver_type": "mumps", "pc_hypre_type": "boomeramg"}, "solver.x")


def test_an_option_petsc_never_read_is_named():
    write_options("options_test_", {"ksp_type": "cg", "ksp_rtoll": 1e-3})
    ksp = PETSc.KSP().create(PETSc.COMM_SELF)
    ksp.setOptionsPrefix("options_test_")
    ksp.setFromOptions()
    check_used("options_test_", ["ksp_type"], "solver.options_test")
    with pytest.raises(ConfigError, match="solver.options_test: PETSc did not use option 'ksp_rtoll'"):
        check_used("options_test_", ["ksp_type", "ksp_rtoll"], "solver.options_test")
    ksp.destroy()


def test_an_option_given_outside_wins_in_any_case():
    # PETSc matches option names in any case: a table's ksp_rtol overwrote PETSC_OPTIONS' -x_KSP_RTOL
    script = ("from petsc4py import PETSc; from primordia.coupling.solvers import write_options; "
              "write_options('outside_test_', {'ksp_rtol': 1e-9, 'ksp_atol': 1e-9}); options = PETSc.Options(); "
              "print(options.getReal('outside_test_ksp_rtol'), options.getReal('outside_test_ksp_atol'))")
    environment = {**os.environ, "PETSC_OPTIONS": "-outside_test_KSP_RTOL 0.01"}
    printed = subprocess.run([sys.executable, "-c", script], env=environment, capture_output=True, text=True,
                             check=True)
    assert printed.stdout.split() == ["0.01", "1e-09"]


@pytest.mark.parametrize("key, value", [
    ("ksp_rtol", -0.5), ("ksp_rtol", 1.0), ("snes_rtol", "abc"), ("ksp_atol", -1e-3), ("snes_stol", True),
    ("ksp_divtol", 0), ("fieldsplit_u_ksp_max_it", -3), ("snes_max_it", 2.5), ("sub_pc_factor_levels", -1),
    ("pc_asm_overlap", "1.5"), ("pc_gasm_overlap", -1), ("pc_gasm_overlap", "default"),
    ("sub_pc_factor_levels", "PETSC_DEFAULT"), ("ksp_rtol", float("nan"))])
def test_a_tolerance_or_count_petsc_would_misread_is_named(key, value):
    with pytest.raises(ConfigError, match=rf"^solver\.x\.{key} must be "):
        check_values({key: value}, "solver.x")


def test_tolerances_and_counts_petsc_reads_as_meant_pass():
    check_values({"ksp_rtol": 1e-8, "snes_rtol": "1e-6", "ksp_atol": 0, "snes_atol": 1e-12, "ksp_divtol": 1e4,
                  "ksp_max_it": 50, "fieldsplit_u_ksp_max_it": "3", "sub_pc_factor_levels": 0, "pc_asm_overlap": 2,
                  "ksp_rtol_extra": -1, "fieldsplit_p_ksp_atol": "DEFAULT", "snes_max_it": "PETSC_DEFAULT"}, "solver.x")


def test_a_table_naming_no_subproblem_is_named_with_the_known_ones():
    check_tables({"chemotaxis_m": {}}, ["chemotaxis_m_", "chemotaxis_f_"])
    with pytest.raises(ConfigError, match=r"unknown solver table \[solver.chemotaxis_n\].*did you mean chemotaxis_m"
                                          r".*known: chemotaxis_f, chemotaxis_m"):
        check_tables({"chemotaxis_n": {}}, ["chemotaxis_m_", "chemotaxis_f_"])


# -- through the real command: one line, exit status 2 ---------------------------------------------
def run(capsys, config, out, *assignments) -> tuple[int, str]:
    from primordia.cli import main

    arguments = ["run", str(config), "--out", str(out), "--no-progress"] + [a for s in assignments for a in ("--set", s)]
    status = main(arguments)
    return status, capsys.readouterr().err


BAD_SOLVER_SETTINGS = [
    (['solver.chemotaxis_m.pc_type="ilu0"'], ["solver.chemotaxis_m", "unknown PC type 'ilu0'"]),
    (['solver.chemotaxis_f.ksp_type="cgg"'], ["solver.chemotaxis_f", "unknown KSP type 'cgg'", "did you mean cg"]),
    # PETSc's type names are case-sensitive: the suggestion is not ("GASM" had none)
    (['solver.chemotaxis_m.pc_type="GASM"'], ["unknown PC type 'GASM'", "did you mean gasm"]),
    # a type petsc4py knows and this PETSc was built without (it suggested the very name before)
    pytest.param(['solver.chemotaxis_m.pc_type="h2opus"'], ["PC type 'h2opus' in pc_type is not available in this PETSc"],
                 marks=pytest.mark.skipif(_try_type(PETSc.PC, "h2opus"), reason="this PETSc has H2OPUS")),
    (["solver.chemotaxis_m.ksp_rtoll=1e-6"], ["solver.chemotaxis_m", "PETSc did not use option 'ksp_rtoll'",
                                             "-chemotaxis_m_ksp_rtoll"]),
    # an option of the several-rank default (GASM) in serial, where block Jacobi reads the options: it said
    # "not read by the chosen solver" without naming the one in use
    (["solver.chemotaxis_m.pc_gasm_overlap=2"], ["PETSc did not use option 'pc_gasm_overlap'",
                                                "(here ksp_type gmres, pc_type bjacobi)"]),
    (['solver.chemotaxis_mm.ksp_type="cg"'], ["unknown solver table [solver.chemotaxis_mm]", "chemotaxis_m"]),
    (['solver.chemotaxis_f.pc_factor_mat_solver_type="pardiso"'], ["factor package 'pardiso'"]),
    (['solver.chemotaxis_f.pc_type="fieldsplit"', "solver.chemotaxis_f.solve_on_one_rank=true"],
     ["solver.chemotaxis_f.solve_on_one_rank", "whole-matrix preconditioner, not fieldsplit"]),
    # values: PETSc takes a negative tolerance for its default and stops with a traceback on what it cannot parse
    (["solver.chemotaxis_m.ksp_rtol=-1"], ["solver.chemotaxis_m.ksp_rtol must be a number in [0, 1), got -1"]),
    (["solver.chemotaxis_m.ksp_max_it=0"], ["solver.chemotaxis_m.ksp_max_it must be an integer >= 1"]),
    # PETSc reads option names in any case: so do the checks (KSP_RTOL = -1 was PETSc's default rtol, unchecked)
    (["solver.chemotaxis_m.KSP_RTOL=-1"], ["solver.chemotaxis_m.ksp_rtol must be a number in [0, 1), got -1"]),
    (["solver.chemotaxis_m.Ksp_Max_It=0"], ["solver.chemotaxis_m.ksp_max_it must be an integer >= 1"]),
    # ... and the SIGABRT of SuperLU_DIST's MC64 went unrefused (exit status 134, no summary)
    (['solver.chemotaxis_f.pc_factor_mat_solver_type="superlu_dist"',
      'solver.chemotaxis_f.MAT_SUPERLU_DIST_ROWPERM="LargeDiag_MC64"'],
     ["mat_superlu_dist_rowperm = 'LargeDiag_MC64'", "aborts the whole process"]),
    (['solver.chemotaxis_m.sub_pc_type="icc"', 'solver.chemotaxis_m.sub={pc_type="lu"}'],
     ["solver.chemotaxis_m: option sub_pc_type is given twice, as sub_pc_type and as sub.pc_type"]),
    (["solver.chemotaxis_m.ksp_gmres_restart=2.5"], ["solver.chemotaxis_m.ksp_gmres_restart", "got 2.5"]),
    (['solver.chemotaxis_m.ksp_gmres_haptol="zz"'], ["solver.chemotaxis_m: PETSc refused the options",
                                                     "zz has no numeric value", "(in ksp_gmres_haptol = 'zz')"]),
    # a sub-solver's option is read when the solve sets it up: PETSc's reason named no option, before
    (['solver.chemotaxis_m.sub_pc_factor_fill="zz"'],
     ["chemotaxis.m: the linear solve failed", "zz has no numeric value (in sub_pc_factor_fill = 'zz')"]),
    # an ordering is read when the factorisation is made: a traceback after the first step's retries, before
    (['solver.chemotaxis_f.pc_factor_mat_ordering_type="zz"'],
     ["solver.chemotaxis_f: matrix ordering 'zz' in pc_factor_mat_ordering_type is not one this PETSc has",
      "(it has ", "nd, "]),
    (['solver.chemotaxis_m.sub_pc_factor_mat_ordering_type="rmc"'],
     ["matrix ordering 'rmc' in sub_pc_factor_mat_ordering_type", "did you mean rcm"]),
    # a preconditioner PETSc takes but cannot set up: the failure carries PETSc's reason, not its code alone
    (['solver.chemotaxis_m.pc_type="composite"'],
     ["chemotaxis.m: the linear solve failed (PETSc error 73: No composite preconditioners supplied"]),
    # accepted by PETSc, answered by SIGABRT in Debian's SuperLU_DIST (no summary, the test process gone)
    (['solver.chemotaxis_f.pc_factor_mat_ordering_type="wbm"'],
     ["solver.chemotaxis_f: pc_factor_mat_ordering_type = 'wbm' calls SuperLU_DIST's MC64", "aborts the whole process",
      "try nd, amd or qmd"]),
    (['solver.chemotaxis_f.pc_factor_mat_solver_type="superlu_dist"',
      'solver.chemotaxis_f.mat_superlu_dist_rowperm="LargeDiag_MC64"'],
     ["mat_superlu_dist_rowperm = 'LargeDiag_MC64'", "aborts the whole process", "try LargeDiag_AWPM"]),
]


@pytest.mark.parametrize("assignments, fragments", BAD_SOLVER_SETTINGS,
                         ids=[(case.values if hasattr(case, "values") else case)[0][0] for case in BAD_SOLVER_SETTINGS])
def test_bad_solver_settings_are_one_line_and_status_2(capsys, small_config, tmp_path, assignments, fragments):
    status, stderr = run(capsys, small_config(), tmp_path / "out", *assignments)
    assert status == 2, stderr
    lines = stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("primordia: error: "), stderr
    for fragment in fragments:
        assert fragment in lines[0], f"{fragment!r} not in {lines[0]!r}"


def test_good_nested_settings_run_and_reach_petsc(capsys, small_config, tmp_path):
    config = small_config(small_config.text + """
[solver.chemotaxis_m]
ksp_type = "gmres"
pc_type = "hypre"
ksp_rtol = 1e-10

[solver.chemotaxis_f]
pc_type = "gamg"
mg_levels = { ksp_type = "chebyshev", ksp_max_it = 2 }
""")
    status, stderr = run(capsys, config, tmp_path / "out")
    assert status == 0, stderr
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["status"] == "completed"
    assert summary["mean_linear_iterations"]["chemotaxis.f"] > 1  # GMRES + AMG, not the default direct solve


@pytest.mark.parametrize("value, printed", [("true", True), ("false", False)])
def test_a_monitor_set_true_prints_and_false_does_not(capfd, small_config, tmp_path, value, printed):
    # "true" was written as PETSc's value: the first step failed, "Unsupported viewer true" (and so for false)
    from primordia.cli import main

    status = main(["run", str(small_config()), "--out", str(tmp_path / "out"), "--no-progress",
                   "--set", f"solver.chemotaxis_m.ksp_converged_reason={value}",
                   "--set", f"solver.chemotaxis_f.ksp_monitor={value}"])
    out, err = capfd.readouterr()
    assert status == 0, err
    assert ("Linear chemotaxis_m_ solve converged" in out) is printed, out
    assert ("0 KSP Residual norm" in out) is printed, out


@pytest.mark.parametrize("assignment, fragment", [
    ('solver.poroelastic_growth_initial.pc_type="hypr"', "unknown PC type 'hypr' in pc_type"),
    ("solver.poroelastic_growth_initial_velocity.ksp_rtol=-1", "ksp_rtol must be a number in [0, 1), got -1"),
])
def test_a_restart_checks_the_tables_of_the_initial_solves_it_does_not_repeat(capsys, tmp_path, assignment,
                                                                            fragment):
    # a restart starts from the checkpoint: no solver read these tables, and they were taken without a word
    from primordia.cli import main

    out = tmp_path / "out"
    status, stderr = run(capsys, EXAMPLES / "ex02a.toml", out, "mesh.cells=[4,4]", "time.t_final=0.2",
                         "output.times=[0.2]", "output.pictures=false")
    assert status == 0, stderr
    status = main(["run", "--restart", str(out), "--no-progress", "--set", "time.t_final=0.4",
                   "--set", "output.times=[0.4]", "--set", assignment])
    lines = capsys.readouterr().err.splitlines()
    assert status == 2 and len(lines) == 1 and fragment in lines[0], lines


def test_linear_biot_in_2d_is_solved_whole_by_one_rank_up_to_eight_ranks():
    # example 1b's constant (u, p) matrix: MUMPS's distributed triangular solves cost more than one rank's
    # serial ones (36 against 19-20 ms a step at 171^2 on 2 ranks); in 3D, or a matrix that changes, MUMPS
    from primordia.physics.base import GATHERED_RANKS
    from primordia.physics.poroelastic_linear import _solver_defaults

    direct = {"ksp_type": "preonly", "pc_type": "lu", "pc_factor_mat_ordering_type": "nd"}
    assert _solver_defaults("lu", 1, 2, constant=True) == direct
    for ranks in (2, GATHERED_RANKS):
        assert _solver_defaults("lu", ranks, 2, constant=True) == {**direct, GATHER: True}
    assert _solver_defaults("lu", GATHERED_RANKS + 1, 2, constant=True) == direct
    assert _solver_defaults("lu", 2, 3, constant=True) == direct
    assert _solver_defaults("lu", 2, 2, constant=False) == direct
    assert GATHER not in _solver_defaults("fixed_stress", 2, 2, constant=True)


def test_a_constant_species_matrix_is_solved_whole_by_one_rank_up_to_eight_ranks():
    # in parallel a diffusing species' constant matrix is gathered to one rank and factorised there once;
    # independent species are solved at once on different ranks (solve_in_turn); from 9 ranks on, AMG
    from primordia.physics.chemotaxis import GATHERED_RANKS, _solver_defaults
    from primordia.physics.kinetics.base import Species

    morphogen = Species("f", "a morphogen", diffusivity="D_f")
    assert _solver_defaults(morphogen, 1, constant=True) == {"ksp_type": "preonly", "pc_type": "lu",
                                                             "pc_factor_mat_ordering_type": "nd"}
    for ranks in (2, GATHERED_RANKS):
        whole = parallel_safe(_solver_defaults(morphogen, ranks, constant=True), parallel=True)
        assert (whole["ksp_type"], whole["pc_type"], whole[GATHER]) == ("preonly", "lu", True)
        assert whole["pc_factor_mat_solver_type"] == "petsc"  # the owner's whole system is serial
    assert _solver_defaults(morphogen, GATHERED_RANKS + 1, constant=True)["pc_type"] == "hypre"
    # a matrix that changes every solve (a growing tissue's metric): CG on each rank's incomplete Cholesky
    # factor, kept while it works, not a factorisation at every solve; AMG from 9 ranks on
    changing = [_solver_defaults(morphogen, ranks, constant=False) for ranks in (1, 2, GATHERED_RANKS + 1)]
    assert [(d["ksp_type"], d["pc_type"], d.get("sub_pc_type")) for d in changing] == [
        ("cg", "bjacobi", "icc"), ("cg", "bjacobi", "icc"), ("cg", "hypre", None)]
    assert [d.get("rebuild_preconditioner_after") for d in changing] == ["fresh+1", "fresh+1", None]
    cells = Species("m", "cells", diffusivity="D_m", attractant="f")
    # rebuilt every step: no factorisation to keep; ILU, with three layers of overlap between ranks (GASM)
    assert [_solver_defaults(cells, ranks, constant=False)["pc_type"] for ranks in (1, 2, 16)] == [
        "bjacobi", "gasm", "gasm"]
    assert [_solver_defaults(cells, ranks, constant=False).get("pc_gasm_overlap") for ranks in (1, 2, 16)] == [
        None, 3, 3]
    # another preconditioner set by the user takes none of additive Schwarz's settings with it
    chosen = combine(_solver_defaults(cells, 2, constant=False), {"pc_type": "bjacobi"})
    assert "pc_gasm_overlap" not in chosen and chosen["pc_type"] == "bjacobi"


def test_a_rebuild_bound_is_a_number_or_a_number_above_the_fresh_count():
    assert flatten({"rebuild_preconditioner_after": 3}, "solver.x") == {"rebuild_preconditioner_after": 3}
    assert flatten({"rebuild_preconditioner_after": "fresh + 02"}, "solver.x") == {"rebuild_preconditioner_after": "fresh+2"}


def test_a_system_gathered_to_one_rank_stays_so_for_another_direct_solve():
    """solve_on_one_rank is the default of f and b (2 to 8 ranks) because one rank's serial factorisation beat
    MUMPS's distributed solves: that holds for any direct solve.  pc_type = "cholesky" dropped it (f and b then went
    to MUMPS on every rank), where ksp_type = "preonly" stayed; an iterative pc_type still drops it."""
    defaults = {"ksp_type": "preonly", "pc_type": "lu", "pc_factor_mat_ordering_type": "nd", GATHER: True}
    assert combine(defaults, {"pc_type": "cholesky"}) == {"ksp_type": "preonly", "pc_type": "cholesky", GATHER: True}
    assert combine(defaults, {"pc_type": "hypre"}) == {"pc_type": "hypre"}
    assert combine(defaults, {"pc_type": "cholesky", GATHER: False})[GATHER] is False



def test_a_factorisation_the_user_makes_of_the_growth_system_is_mumps_at_once():
    """pc_type = "lu" over the growth's Schur split met a zero pivot (the psi block) in PETSc's unpivoted LU, then
    switched to MUMPS with a warning: example 4 at 10 x 10 x 2 boxes, 319-323 against 176-186 ms of linear algebra
    a step.  The split's defaults name the package a factorisation of the system needs, and it stays."""
    from primordia.physics.poroelastic_growth import SCHUR_FIELDSPLIT

    defaults = flatten(SCHUR_FIELDSPLIT, "defaults")
    for user in ({"pc_type": "lu"}, {"pc_type": "cholesky", "ksp_type": "preonly"}):
        options = parallel_safe(combine(defaults, user), parallel=False)
        assert options["pc_factor_mat_solver_type"] == "mumps" and "fieldsplit_u_pc_type" not in options
    assert "pc_factor_mat_solver_type" not in combine(defaults, {"pc_type": "hypre"})
    assert combine(defaults, {"pc_type": "lu", "pc_factor_mat_solver_type": "petsc"})[
        "pc_factor_mat_solver_type"] == "petsc"  # the user's own word wins
    # a package chosen for the factorisation a default makes goes with it, as before
    assert "pc_factor_mat_solver_type" not in combine({"pc_type": "lu", "pc_factor_mat_solver_type": "mumps"},
                                                      {"pc_type": "ilu"})


@pytest.mark.parametrize("assignments, told", [
    (['physics.chemotaxis.solve="coupled"', 'physics.chemotaxis.flux_scheme="galerkin"',
      'solver.chemotaxis_m.pc_type="hypre"'],
     '[solver.chemotaxis_m] has no effect: solve = "coupled" solves the species together ([solver.chemotaxis])'),
    (['solver.chemotaxis.pc_type="lu"'],
     '[solver.chemotaxis] has no effect: solve = "split" solves the species one by one ([solver.chemotaxis_SPECIES])'),
])
def test_a_table_of_a_subproblem_another_setting_makes_is_one_warning(capsys, small_config, tmp_path, assignments,
                                                                      told):
    """As an option another choice leaves without effect (a config switched to solve = "coupled" keeps its
    [solver.chemotaxis_m]): it was refused as an unknown table, at the run's set-up only, not by --dry-run."""
    status, stderr = run(capsys, small_config(), tmp_path / "out", *assignments)
    assert status == 0, stderr
    assert stderr.splitlines() == [f"primordia: warning: {told}"]
    # its values are still checked, and a table no setting makes is still refused
    status, stderr = run(capsys, small_config(), tmp_path / "again", *assignments[:-1],
                         assignments[-1].replace('"hypre"', '"hypr"').replace('"lu"', '"lux"'))
    assert status == 2 and "unknown PC type" in stderr.splitlines()[-1], stderr
    status, stderr = run(capsys, small_config(), tmp_path / "typo", *assignments[:-1],
                         assignments[-1].replace("solver.chemotaxis", "solver.chemotaxsi"))
    assert status == 2 and "unknown solver table [solver.chemotaxsi" in stderr, stderr


def test_an_option_of_a_split_that_was_not_read_names_the_splits_solver():
    """``fieldsplit_u = {pc_factor_levels = 2}`` under the growth's Schur split was refused "(here ksp_type gmres,
    pc_type fieldsplit)": the outer solver, where the split's own (preonly, gamg) is the one that did not read it."""
    from primordia.coupling.solvers import solver_reading

    matrix = PETSc.Mat().createAIJ((4, 4), nnz=1, comm=PETSc.COMM_SELF)
    for row in range(4):
        matrix.setValue(row, row, 2.0)
    matrix.assemble()
    options = PETSc.Options()
    options.setValue("qa_split_fieldsplit_u_ksp_type", "preonly")
    options.setValue("qa_split_fieldsplit_u_pc_type", "jacobi")
    try:
        ksp = PETSc.KSP().create(PETSc.COMM_SELF)
        ksp.setOptionsPrefix("qa_split_")
        ksp.setOperators(matrix)
        pc = ksp.getPC()
        pc.setType("fieldsplit")
        for name, rows in (("u", [0, 1]), ("p", [2, 3])):
            pc.setFieldSplitIS((name, PETSc.IS().createGeneral(rows, comm=PETSc.COMM_SELF)))
        ksp.setFromOptions()
        ksp.setUp()
        assert solver_reading(ksp, "qa_split_fieldsplit_u_pc_factor_levels") == (
            "fieldsplit_u_ksp_type preonly, fieldsplit_u_pc_type jacobi")
        assert solver_reading(ksp, "qa_split_pc_factor_levels") == "ksp_type gmres, pc_type fieldsplit"
    finally:
        for name in ("qa_split_fieldsplit_u_ksp_type", "qa_split_fieldsplit_u_pc_type"):
            options.delValue(name)
