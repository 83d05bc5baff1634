"""``primordia run --dry-run`` refuses what the run's set-up refuses.

A user checks a config with ``--dry-run`` before submitting a cluster job: an input it passes that the run
then refuses at set-up costs a queue slot.  Each case here is a config on a 2 x 2 mesh (with a plugin given by
``-p``, on scikit-fem), through the real command: the dry run and the run must both refuse it, in the same line.
"""

from __future__ import annotations

import textwrap

import pytest

from cli_checks import assert_one_line_error


def _inputs(small_config, tmp_path, plugin: str, physics: list[str]):
    """The plugin file and the config of one case: the small config's run of ``physics`` on 2 x 2 squares, on
    scikit-fem (a kinetics and its parameters only for chemotaxis)."""
    plugin_file = tmp_path / "case_plugin.py"
    plugin_file.write_text(textwrap.dedent(plugin))
    text = small_config.text.replace('physics = ["chemotaxis"]', f"physics = {physics}\nbackend = \"skfem\"")
    text = text.replace("cells = [8, 8]", "cells = [2, 2]").replace("'", '"')
    if "chemotaxis" not in physics:
        for section in ('[kinetics]\nname = "painter2018"\n', "[parameters]\nm0 = 0.75\nD_m = 0.03\n"):
            text = text.replace(section, "")
    return plugin_file, small_config(text)


def _both_refuse(primordia_cli, tmp_path, plugin_file, config, *fragments: str) -> None:
    """The dry run and the run refuse the input with the same one line."""
    dry = primordia_cli("-p", plugin_file, "run", config, "--out", tmp_path / "out", "--dry-run")
    ran = primordia_cli("-p", plugin_file, "run", config, "--out", tmp_path / "out", "--no-progress")
    assert assert_one_line_error(dry, *fragments) == assert_one_line_error(ran, *fragments)


TWICE = """\
from primordia.core.parameters import Parameter
from primordia.core.plugins import hookimpl
from primordia.physics.base import Coupling


class Twice(Coupling):
    name = "twice"
    parameters = (Parameter("k_t", 1.0, "a rate (1/time)"), Parameter("k_t", {second}, "a rate (1/time)"))

    def setup(self, disc):
        pass


@hookimpl
def primordia_physics():
    return [Twice]
"""


@pytest.mark.parametrize("second, told", [(2.0, "(defaults 1.0 and 2.0)"), (1.0, "(default 1.0)")])
def test_a_parameter_one_module_declares_twice_is_told_as_such(primordia_cli, small_config, tmp_path, second,
                                                              told):
    """"parameter k_t is declared by physics twice (default 1) and by physics twice (default 2)" named the module
    as two owners, and with equal defaults the model took the name twice, two descriptions, without a word."""
    plugin_file, config = _inputs(small_config, tmp_path, TWICE.format(second=second), ["chemotaxis", "twice"])
    _both_refuse(primordia_cli, tmp_path, plugin_file, config, "returned 'twice', which declares parameter k_t twice",
                 told)
    listed = primordia_cli("-p", plugin_file, "plugins")
    assert_one_line_error(listed, "declares parameter k_t twice")


QUIET = """\
import ufl

from primordia.core.plugins import hookimpl
from primordia.physics.base import Coupling, FieldSpec, Physics, Subproblem


class Quiet(Physics):
    '''Owns q, whose balance law reads no contributed terms.'''

    name = "quiet"

    def fields(self):
        return [FieldSpec("q")]

    def setup(self, disc):
        self.disc = disc

    def initialise(self, disc):
        disc.interpolate("q", 0.0)

    def subproblems(self):
        disc = self.disc
        residual = (disc.field("q") - disc.previous("q")) / disc.dt * disc.test("q") * disc.dx
        unknown = disc.unknown("q")
        return [Subproblem(name="quiet", unknown=unknown, residual=residual,
                           jacobian=ufl.derivative(residual, unknown))]


class Push(Coupling):
    '''Adds a source to the balance law of ``target``.'''

    name = "push"
    target = "{target}"
    requires = (target,)

    def setup(self, disc):
        disc.contribute(self.target, lambda v: 1.0 * v * disc.dx, by=self.name)


@hookimpl
def primordia_physics():
    return [Quiet, Push]
"""


def test_a_term_added_to_a_law_that_reads_none_is_refused_by_the_dry_run(primordia_cli, small_config, tmp_path):
    """--dry-run said "the input is valid" and the run stopped at set-up: the modules' forms were not stated."""
    plugin_file, config = _inputs(small_config, tmp_path, QUIET.format(target="q"), ["quiet", "push"])
    _both_refuse(primordia_cli, tmp_path, plugin_file, config,
                 "push adds a term to the balance law of 'q', but quiet does not read contributed terms")


def test_a_term_added_to_a_law_that_reads_it_passes_the_dry_run(primordia_cli, small_config, tmp_path):
    plugin_file, config = _inputs(small_config, tmp_path, QUIET.format(target="m"), ["chemotaxis", "push"])
    dry = primordia_cli("-p", plugin_file, "run", config, "--out", tmp_path / "out", "--dry-run")
    assert dry.returncode == 0 and "the input is valid" in dry.stdout, dry.stderr
    assert not (tmp_path / "out").exists()  # nothing written


def test_strang_with_one_module_that_solves_anything_is_refused_by_the_dry_run(primordia_cli, small_config, tmp_path):
    """Refused by the scheme once its solvers were made (the forms compiled): --dry-run said "the input is valid"."""
    config = small_config(small_config.text.replace("cells = [8, 8]", "cells = [2, 2]"))
    for dry_run in (["--dry-run"], ["--no-progress"]):
        result = primordia_cli("run", config, "--out", tmp_path / "out", "--set", 'coupling.scheme="strang"', *dry_run)
        assert_one_line_error(result, "the strang scheme needs at least two physics modules with subproblems")


def test_an_output_directory_holding_a_run_is_refused_by_the_dry_run_as_by_the_run(primordia_cli, small_config,
                                                                                   tmp_path):
    """--dry-run said "the input is valid ...; OUT already holds a run that ended ...", exit 0, where the run
    (without --overwrite or --restart) stopped at once."""
    config = small_config(small_config.text.replace("cells = [8, 8]", "cells = [2, 2]"))
    out = tmp_path / "out"
    assert primordia_cli("run", config, "--out", out, "--no-progress").returncode == 0
    dry = primordia_cli("run", config, "--out", out, "--dry-run")
    ran = primordia_cli("run", config, "--out", out, "--no-progress")
    fragments = ("already holds a run that ended: completed", "use --overwrite to replace it")
    assert assert_one_line_error(dry, *fragments) == assert_one_line_error(ran, *fragments)
    replacing = primordia_cli("run", config, "--out", out, "--dry-run", "--overwrite")
    assert replacing.returncode == 0 and "which --overwrite replaces; nothing was run" in replacing.stdout
    assert (out / "summary.json").is_file()  # the dry run removed nothing


@pytest.mark.parametrize("assignments, fragments", [
    (['solver.chemotaxis_mm.ksp_type="cg"'],
     ["unknown solver table [solver.chemotaxis_mm]", "did you mean chemotaxis_m"]),
    (['coupling.scheme="monolithic"', 'physics.chemotaxis.flux_scheme="galerkin"', 'solver.chemotaxis_m.ksp_type="cg"'],
     ["unknown solver table [solver.chemotaxis_m]", "(known: monolithic)"]),
], ids=["misspelt", "another-scheme-s"])
def test_a_solver_table_naming_no_subproblem_is_refused_by_the_dry_run(primordia_cli, small_config, tmp_path,
                                                                       assignments, fragments):
    """The subproblems' options prefixes exist once the modules state their forms: --dry-run said "the input is
    valid" to a misspelt [solver.NAME] table, and the run stopped at set-up."""
    config = small_config(small_config.text.replace("cells = [8, 8]", "cells = [2, 2]"))
    settings = [argument for assignment in assignments for argument in ("--set", assignment)]
    dry = primordia_cli("run", config, "--out", tmp_path / "out", "--dry-run", *settings)
    ran = primordia_cli("run", config, "--out", tmp_path / "out", "--no-progress", *settings)
    assert assert_one_line_error(dry, *fragments) == assert_one_line_error(ran, *fragments)


def test_the_solver_tables_of_a_scheme_s_subproblems_pass_the_dry_run(primordia_cli, small_config, tmp_path):
    config = small_config(small_config.text.replace("cells = [8, 8]", "cells = [2, 2]"))
    for settings in (["--set", 'solver.chemotaxis_m.ksp_type="cg"'],
                     ["--set", 'coupling.scheme="monolithic"', "--set", 'physics.chemotaxis.flux_scheme="galerkin"',
                      "--set", 'solver.monolithic.ksp_type="gmres"']):
        dry = primordia_cli("run", config, "--out", tmp_path / "out", "--dry-run", *settings)
        assert dry.returncode == 0 and "the input is valid" in dry.stdout, dry.stderr


def test_a_module_whose_initialise_fails_is_refused_by_the_dry_run(primordia_cli, small_config, tmp_path):
    """The run sets the fields' values (``initialise``) before any solve: a plugin's slip there passed --dry-run."""
    plugin = QUIET.format(target="q").replace('disc.interpolate("q", 0.0)', 'disc.interpolate("qq", 0.0)')
    plugin_file, config = _inputs(small_config, tmp_path, plugin, ["quiet"])
    _both_refuse(primordia_cli, tmp_path, plugin_file, config,
                 "physics quiet: initialise: field 'qq' is required but no physics module of this model provides it")


@pytest.mark.parametrize("change, fragment", [
    (lambda fields: fields.pop("m/previous"), "it holds no m/previous, which this run reads"),
    (lambda fields: fields.update({"m/previous": fields["m/previous"][:-1]}), "its fields are laid out differently"),
], ids=["older-primordia", "other-layout"])
def test_a_checkpoint_whose_fields_do_not_fit_is_refused_by_the_dry_run_of_its_restart(primordia_cli, small_config,
                                                                                       tmp_path, change, fragment):
    """The restart takes the fields once the model is discretised: --restart --dry-run said "the input is valid"
    to a checkpoint of an older primordia, which the restart then refused."""
    from primordia.core import checkpoint

    config = small_config(small_config.text.replace("cells = [8, 8]", "cells = [2, 2]"))
    out = tmp_path / "out"
    assert primordia_cli("run", config, "--out", out, "--no-progress").returncode == 0
    tree = checkpoint.read(out / checkpoint.CHECKPOINT_FILE)
    change(tree["fields"])
    change(tree["layout"])
    checkpoint.write(out / checkpoint.CHECKPOINT_FILE, tree)
    dry = primordia_cli("run", "--restart", out, "--dry-run", "--set", "time.t_final=1.4")
    ran = primordia_cli("run", "--restart", out, "--no-progress", "--set", "time.t_final=1.4")
    assert assert_one_line_error(dry, fragment) == assert_one_line_error(ran, fragment)


def test_an_algebraic_operator_under_the_monolithic_scheme_is_refused_by_the_dry_run(primordia_cli, small_config,
                                                                                      tmp_path):
    """Refused by the scheme once the modules' subproblems were built at set-up: --dry-run said "the input is
    valid"."""
    plugin = QUIET.format(target="q").replace(
        "from primordia.physics.base import", "from primordia.physics.base import AlgebraicOperator,").replace(
        "unknown))]", "unknown), operator=Nothing())]") + textwrap.dedent('''

        class Nothing(AlgebraicOperator):
            def update(self):
                pass

            def matrix(self):
                raise AssertionError("not asked for before the solver is made")
        ''')
    plugin_file, config = _inputs(small_config, tmp_path, plugin, ["quiet"])
    config.write_text(config.read_text() + '\n[coupling]\nscheme = "monolithic"\n')
    _both_refuse(primordia_cli, tmp_path, plugin_file, config,
                 "the monolithic scheme cannot include quiet: its algebraic operator acts on its own field alone")


@pytest.mark.parametrize("assignments, fragments", [
    (['solver.chemotaxis_m.splits=[["m"]]'],
     ['solver.chemotaxis_m.splits names the splits of pc_type = "fieldsplit"', "this solver's pc_type is 'bjacobi'"]),
    (['coupling.scheme="monolithic"', 'physics.chemotaxis.flux_scheme="galerkin"',
      'solver.monolithic.solve_on_one_rank=true'],
     ["solver.monolithic.solve_on_one_rank: a Newton solve is not gathered to one rank"]),
    (['coupling.scheme="monolithic"', 'physics.chemotaxis.flux_scheme="galerkin"',
      'solver.monolithic.rebuild_preconditioner_after=3'],
     ['solver.monolithic.rebuild_preconditioner_after needs a Krylov method', "would freeze the tangent"]),
    (['solver.chemotaxis_f.rebuild_preconditioner_after=3'],
     ['solver.chemotaxis_f.rebuild_preconditioner_after needs a Krylov method', "with an old matrix"]),
], ids=["splits-without-fieldsplit", "monolithic-gathered", "kept-newton-preonly", "kept-linear-preonly"])
def test_options_a_solver_refuses_before_it_is_made_are_refused_by_the_dry_run(primordia_cli, small_config, tmp_path,
                                                                              assignments, fragments):
    """The solver refuses them as it is made, from the options alone: --dry-run, which makes none, said "the input
    is valid"."""
    config = small_config(small_config.text.replace("cells = [8, 8]", "cells = [2, 2]"))
    settings = [argument for assignment in assignments for argument in ("--set", assignment)]
    dry = primordia_cli("run", config, "--out", tmp_path / "out", "--dry-run", *settings)
    ran = primordia_cli("run", config, "--out", tmp_path / "out", "--no-progress", *settings)
    assert assert_one_line_error(dry, *fragments) == assert_one_line_error(ran, *fragments)


@pytest.mark.parametrize("assignments, fragments", [
    (['solver.chemotaxis_m.ksp_gmres_haptol="zz"'],
     ["solver.chemotaxis_m: PETSc refused the options: Input string zz has no numeric value",
      "(in ksp_gmres_haptol = 'zz')"]),
    (['coupling.scheme="monolithic"', 'physics.chemotaxis.flux_scheme="galerkin"',
      'solver.monolithic.snes_linesearch_type="nosuch"'],
     ["solver.monolithic: PETSc refused the options", "(in snes_linesearch_type = 'nosuch')"]),
    # a value a default shares (m's sub_pc_factor_levels = 1) named no option
    (['solver.chemotaxis_m.ksp_monitor=1'],
     ["solver.chemotaxis_m: PETSc refused the options: Unsupported viewer 1 (in ksp_monitor = '1')"]),
], ids=["linear", "newton", "a-default-s-value"])
def test_a_value_petsc_cannot_read_is_refused_by_the_dry_run(primordia_cli, small_config, tmp_path, assignments,
                                                             fragments):
    """PETSc reads the options as the solver is made, which the dry run never does: it said "the input is valid"."""
    config = small_config(small_config.text.replace("cells = [8, 8]", "cells = [2, 2]"))
    settings = [argument for assignment in assignments for argument in ("--set", assignment)]
    dry = primordia_cli("run", config, "--out", tmp_path / "out", "--dry-run", *settings)
    ran = primordia_cli("run", config, "--out", tmp_path / "out", "--no-progress", *settings)
    assert assert_one_line_error(dry, *fragments) == assert_one_line_error(ran, *fragments)
