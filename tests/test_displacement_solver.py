"""The displacement solve that keeps its preconditioner (preset gamg-reuse): it agrees with a
fresh solve to the solver tolerance across a small crack run, its incremental assembly gives the
matrix of a full one, the reaction from the loaded cells equals the one from all cells, and the
preconditioner is rebuilt when the policy says so and only then."""

import copy

import numpy as np
import pytest
from conftest import build_problem
from dolfinx.fem import petsc as fem_petsc

from ifenn.config import ConfigError, validate_config
from ifenn.fem.phase_field import FEMPhaseField


@pytest.fixture
def presets(quick_config):
    return quick_config["solver"]["linear_solver_presets"]


def _pair(quick_spec, presets, tmp_path, reuse_settings=None):
    spec = quick_spec("snt1-I")
    kept = copy.deepcopy(presets["gamg-reuse"])
    kept["displacement_reuse"].update(reuse_settings or {})
    fresh = copy.deepcopy(kept)
    del fresh["displacement_reuse"]   # same KSP options, preconditioner rebuilt every solve
    a, _ = build_problem(spec["scene"], spec["material"], kept, tmp_path, "kept")
    b, _ = build_problem(spec["scene"], spec["material"], fresh, tmp_path, "fresh")
    return spec, a, b


def _crack_run(kept, reference, step, loads):
    """Both problems solve each load with the same phase field (the kept one's FEM step drives);
    returns the largest displacement difference / the reference's largest displacement, the
    (kept, reference) reaction forces of every increment and the Krylov iterations of the kept
    problem's solves that kept their preconditioner."""
    worst, forces, kept_solves = 0.0, [], []
    for u in loads:
        reference.phase_field_gp.x.array[:] = kept.phase_field_gp.x.array
        refreshes = kept.reuse.refreshes
        iterations = kept.solve_displacement(u)
        if kept.reuse.refreshes == refreshes:
            kept_solves.append(iterations)
        reference.solve_displacement(u)
        scale = np.abs(reference.displacement.x.array).max()
        worst = max(worst, np.abs(kept.displacement.x.array - reference.displacement.x.array).max() / scale)
        forces.append((kept.reaction_force(), reference.reaction_force()))
        kept.update_history()
        step.solve()
        kept.accept_increment()
    return worst, np.array(forces), kept_solves


def test_kept_preconditioner_agrees_with_a_fresh_solve_across_a_crack_run(quick_spec, presets, tmp_path):
    """Both problems take the same phase field each increment (the kept one's FEM step drives);
    the displacements agree to the solver tolerance while the crack runs through."""
    spec, kept, fresh = _pair(quick_spec, presets, tmp_path)
    step = FEMPhaseField(kept, presets["gamg-reuse"]["phase_field"])
    rtol = presets["gamg-reuse"]["displacement"]["ksp_rtol"]
    worst, forces, _ = _crack_run(kept, fresh, step, spec["load"])
    np.testing.assert_allclose(forces[:, 0], forces[:, 1], rtol=1e3 * rtol, atol=1e-6)
    assert step.phase_field_max() > 0.99, "the crack did not run: the scene tests nothing"
    assert worst < 1e3 * rtol
    # the quick scene's steps are coarse (the crack crosses it in ~10 increments): the policy
    # rebuilds often while the stiffness drops, and keeps the hierarchy in between
    assert kept.reuse.reasons[0] == "first"
    assert set(kept.reuse.reasons[1:]) <= {"stiffness", "iterations"}
    assert kept.reuse.refreshes < len(spec["load"])


def test_incremental_assembly_gives_the_full_matrix(quick_spec, presets, tmp_path):
    spec, kept, fresh = _pair(quick_spec, presets, tmp_path)
    rng = np.random.default_rng(1)
    for k, fraction in enumerate((0.0, 0.3, 0.8, 0.05, 0.0)):   # 0.8: more than half, a full assembly
        phi = kept.phase_field_gp.x.array
        changed = rng.random(phi.size) < fraction
        phi[changed] = np.minimum(1.0, phi[changed] + rng.random(changed.sum()))
        fresh.phase_field_gp.x.array[:] = phi
        kept.solve_displacement(1e-3 * (k + 1))
        fresh.solve_displacement(1e-3 * (k + 1))
        difference = kept.A_u.copy()
        difference.axpy(-1.0, fresh.A_u)
        assert difference.norm() <= 1e-12 * fresh.A_u.norm()
        if k > 0 and fraction == 0.0:
            assert kept.stiffness.changed_cells == 0


def test_reaction_from_the_loaded_cells_equals_the_one_from_all_cells(quick_spec, presets, tmp_path):
    import ufl
    from dolfinx import fem

    from ifenn.models import phase_field_model

    spec, kept, _ = _pair(quick_spec, presets, tmp_path)
    kept.phase_field_gp.x.array[:] = np.random.default_rng(2).random(kept.phase_field_gp.x.array.size) * 0.5
    kept.solve_displacement(2e-3)
    v = ufl.TestFunction(kept.V)
    everywhere = fem.form(phase_field_model().equilibrium_form(kept.displacement, v, kept.phase_field_gp, kept.material) * kept.dx)
    vector = fem_petsc.assemble_vector(everywhere)
    full = float(vector.array_r[kept.loaded_dofs].sum())
    assert kept.reaction_force() == pytest.approx(full, rel=1e-12)


def test_refreshes_after_a_big_stiffness_change_and_not_without_one(quick_spec, presets, tmp_path):
    spec, kept, _ = _pair(quick_spec, presets, tmp_path, {"refresh_stiffness_change": 0.05, "refresh_iterations": 1000})
    kept.solve_displacement(1e-3)
    assert kept.reuse.reasons == ["first"]
    for u in (1.5e-3, 2e-3, 2e-3):   # no change of phi: the hierarchy is kept
        kept.solve_displacement(u)
    assert kept.reuse.refreshes == 1
    q = kept.q_dofs[: kept.n_cells_owned]
    kept.phase_field_gp.x.array[q[: len(q) // 5]] = 0.9   # a fifth of the cells nearly broken: g moved by far more than 5 %
    kept.solve_displacement(2e-3)
    assert kept.reuse.reasons == ["first", "stiffness"]
    kept.solve_displacement(2.1e-3)
    assert kept.reuse.refreshes == 2


def test_refreshes_when_the_iterations_grow(quick_spec, presets, tmp_path):
    spec, kept, _ = _pair(quick_spec, presets, tmp_path, {"refresh_stiffness_change": 10.0, "refresh_iterations": 1})
    kept.solve_displacement(1e-3)
    kept.solve_displacement(2e-3)   # the first solve took more than one iteration
    assert kept.reuse.reasons == ["first", "iterations"]


def test_a_kept_preconditioner_needs_a_krylov_solve(quick_config):
    config = copy.deepcopy(quick_config)
    preset = config["solver"]["linear_solver_presets"]["gamg-reuse"]
    preset["displacement"] = {"ksp_type": "preonly", "pc_type": "cholesky"}
    with pytest.raises(ConfigError, match="displacement_reuse"):
        validate_config(config)
    config = copy.deepcopy(quick_config)
    config["solver"]["linear_solver_presets"]["gamg-reuse"]["displacement_reuse"]["refresh_iterations"] = 0
    with pytest.raises(ConfigError, match="refresh_iterations"):
        validate_config(config)


@pytest.mark.parametrize("matrix", ["baij", "aij"])
def test_kept_cholesky_factor_agrees_with_a_direct_solve_across_a_crack_run(quick_spec, presets, tmp_path, matrix):
    """Preset cholesky-reuse (ifenn.fem.factor): CG on the current matrix with a kept nested-
    dissection Cholesky factor gives the direct solve's displacements and forces to ~1e-9 while
    the crack runs through, factors far less often than it solves, and takes the block (SBAIJ)
    path on a BAIJ matrix, PETSc's AIJ Cholesky on an AIJ one."""
    spec = quick_spec("snt1-I")
    kept_preset = copy.deepcopy(presets["cholesky-reuse"])
    kept_preset["displacement_matrix"] = matrix
    kept, _ = build_problem(spec["scene"], spec["material"], kept_preset, tmp_path, "kept")
    direct, _ = build_problem(spec["scene"], spec["material"], presets["direct"], tmp_path, "direct")
    assert kept.A_u.getType() == ("seqbaij" if matrix == "baij" else "seqaij")
    step = FEMPhaseField(kept, kept_preset["phase_field"])
    worst_u, forces, kept_solves = _crack_run(kept, direct, step, spec["load"])
    worst_force = (np.abs(forces[:, 0] - forces[:, 1]) / np.abs(forces[:, 1])).max()
    assert step.phase_field_max() > 0.99, "the crack did not run: the scene tests nothing"
    assert worst_u < 1e-8 and worst_force < 1e-8
    context = kept.ksp_u.getPC().getPythonContext()
    # the factor really is kept: a solve on a matrix that moved since the factor needs more CG
    # iterations than one (a factor silently redone at every apply, of the matrix itself, gives 1)
    assert kept_solves and max(kept_solves) > 1
    assert (context.order is not None) == (matrix == "baij")
    # the quick scene's 30 coarse steps move g by more than 5 % most increments: fewer factors
    # than solves, not many fewer (at paper scale ~60 of 700, docs/decisions.md)
    assert context.factorizations == kept.reuse.refreshes < len(spec["load"])
    assert kept.reuse.reasons[0] == "first" and set(kept.reuse.reasons[1:]) <= {"stiffness", "iterations"}
    # a fresh factor of the matrix itself is its exact inverse: CG stops after one iteration
    kept.reuse._built_with = None   # as before the first solve: refresh
    kept.solve_displacement(spec["load"][-1])
    assert kept.displacement_iterations <= 1


def test_a_run_with_the_kept_cholesky_factor_exits_cleanly(quick_spec, presets, tmp_path):
    """PETSc destroys the objects Python left it after the interpreter is gone; a python
    preconditioner must be detached before (ifenn.fem.factor._detach), or the process crashes at
    exit with a finished run's outputs written (exit code 59: a failed job to snakemake)."""
    import json
    import subprocess
    import sys

    spec = quick_spec("snt1-I")
    spec.update(name="exit", load=spec["load"][:3], save_fields=[], linear_solvers="cholesky-reuse", petsc=presets["cholesky-reuse"])
    (tmp_path / "spec.json").write_text(json.dumps(spec))
    _, mesh = build_problem(spec["scene"], spec["material"], presets["direct"], tmp_path, "mesh")
    done = subprocess.run([sys.executable, "-m", "ifenn", "fem", "--spec", str(tmp_path / "spec.json"), "--mesh", str(mesh),
                           "--out", str(tmp_path / "run")], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    assert (tmp_path / "run" / "history.csv").exists()


def test_a_python_preconditioner_must_be_importable(quick_config):
    config = copy.deepcopy(quick_config)
    config["solver"]["linear_solver_presets"]["cholesky-reuse"]["displacement"]["pc_python_type"] = "ifenn.fem.factor.NoSuchFactor"
    with pytest.raises(ConfigError, match="pc_python_type"):
        validate_config(config)
