"""The staggered FEM run: agreement between linear solvers and MPI layouts, resuming after
a kill, clean failure on a diverging solve, and slit faces that open under load."""

import json
import os
import shutil
import signal
import subprocess
import sys
import time

import h5py
import numpy as np
import pandas as pd
import pytest

from ifenn.fem.mesh import build_mesh, write_mesh
from ifenn.fem.problem import SolverDivergedError
from ifenn.fem.solver import HISTORY_COLUMNS, run_fem

ENV = {**os.environ, "OMPI_ALLOW_RUN_AS_ROOT": "1", "OMPI_ALLOW_RUN_AS_ROOT_CONFIRM": "1", "OMP_NUM_THREADS": "1"}
# a guard against a hang, not a speed limit: CI's own limit (90 min); the suite must pass on a
# slow or busy machine
HANG_GUARD_S = 5400


def _prepare(spec, tmp_path, name="run"):
    mesh = tmp_path / f"{spec['scene_name']}.xdmf"
    if not mesh.exists():
        write_mesh(build_mesh(spec["scene"]), mesh)
    spec_path = tmp_path / f"{name}.json"
    spec_path.write_text(json.dumps(spec))
    return ["-m", "ifenn", "fem", "--spec", str(spec_path), "--mesh", str(mesh), "--out", str(tmp_path / name), "--no-progress"]


def _history(tmp_path, name):
    return pd.read_csv(tmp_path / name / "history.csv")


@pytest.fixture(scope="module")
def serial_reference(tmp_path_factory, quick_config):
    from ifenn.config import fem_run_spec

    tmp = tmp_path_factory.mktemp("reference")
    spec = fem_run_spec(quick_config, "snt1-I")
    subprocess.run([sys.executable, *_prepare(spec, tmp, "serial")], check=True, env=ENV)
    return spec, tmp, _history(tmp, "serial")


def test_history_columns_and_a_crack_that_runs(serial_reference):
    _, _, history = serial_reference
    assert list(history.columns) == HISTORY_COLUMNS
    peak = history.reaction_force.idxmax()
    assert 0 < peak < len(history) - 1
    assert history.reaction_force.iloc[-1] < 0.2 * history.reaction_force.max()  # the specimen is cut
    assert history.phi_max.iloc[-1] > 0.99
    # AT2 has no elastic threshold: the secant stiffness falls monotonically from the start
    stiffness = (history.reaction_force / history.u).to_numpy()
    assert (np.diff(stiffness[: peak + 1]) < 0).all()


def test_mpi_two_ranks_match_serial(serial_reference, quick_config):
    """With a direct solver (MUMPS) two ranks reproduce the serial run to round-off; with
    CG + GAMG the force curves agree within the solver tolerance."""
    spec, tmp, serial = serial_reference
    args = _prepare(spec, tmp, "parallel")
    subprocess.run(["mpirun", "-n", "2", "--oversubscribe", sys.executable, *args], check=True, env=ENV, timeout=HANG_GUARD_S)
    parallel = _history(tmp, "parallel")
    scale = serial.reaction_force.abs().max()
    np.testing.assert_allclose(parallel.reaction_force, serial.reaction_force, atol=1e-5 * scale)

    mumps = {**spec, "petsc": quick_config["solver"]["linear_solver_presets"]["mumps"]}
    subprocess.run([sys.executable, *_prepare(mumps, tmp, "mumps1")], check=True, env=ENV)
    args = _prepare(mumps, tmp, "mumps2")
    subprocess.run(["mpirun", "-n", "2", "--oversubscribe", sys.executable, *args], check=True, env=ENV, timeout=HANG_GUARD_S)
    one, two = _history(tmp, "mumps1"), _history(tmp, "mumps2")
    np.testing.assert_allclose(two.reaction_force, one.reaction_force, rtol=1e-9, atol=1e-9 * scale)
    with h5py.File(tmp / "mumps1" / "fields.h5") as a, h5py.File(tmp / "mumps2" / "fields.h5") as b:
        assert sorted(a) == sorted(b)
        for group in a:
            for key in ("phase_field_gp", "history", "phase_field", "displacement"):
                np.testing.assert_allclose(b[group][key][()], a[group][key][()], rtol=1e-6, atol=1e-9 * np.abs(a[group][key][()]).max())


def test_direct_and_iterative_solvers_agree(quick_config, serial_reference, tmp_path):
    spec, _, iterative = serial_reference
    direct_spec = {**spec, "petsc": quick_config["solver"]["linear_solver_presets"]["direct"]}
    direct = pd.DataFrame(run_fem(direct_spec, _mesh(spec, tmp_path), tmp_path / "direct", progress=False))
    scale = direct.reaction_force.abs().max()
    # CG + GAMG at rtol 1e-8: force curves within 1e-5 of the peak (the speed target asks 1e-3)
    np.testing.assert_allclose(iterative.reaction_force, direct.reaction_force, atol=1e-5 * scale)


def _mesh(spec, tmp_path):
    path = tmp_path / f"{spec['scene_name']}.xdmf"
    write_mesh(build_mesh(spec["scene"]), path)
    return path


def test_killed_run_resumes_to_the_same_history(quick_spec, quick_config, tmp_path):
    # A direct solver makes the resumed run repeat the uninterrupted one to round-off, so
    # any state missing from the checkpoint would show.
    spec = quick_spec("snt1-I", load=list(np.linspace(2e-4, 1.4e-2, 70)), checkpoint_every=4, save_fields=[40],
                      petsc=quick_config["solver"]["linear_solver_presets"]["direct"])
    reference = pd.DataFrame(run_fem(spec, _mesh(spec, tmp_path), tmp_path / "reference", progress=False))
    args = _prepare(spec, tmp_path, "killed")
    process = subprocess.Popen([sys.executable, *args], env=ENV)
    checkpoint = tmp_path / "killed" / ".work" / "checkpoint.npz"
    deadline = time.time() + HANG_GUARD_S
    while not checkpoint.exists() and process.poll() is None and time.time() < deadline:
        time.sleep(0.01)
    process.send_signal(signal.SIGKILL)
    process.wait()
    assert not (tmp_path / "killed" / "history.csv").exists(), "the run finished before it could be killed"
    with np.load(checkpoint) as data:
        resumed_from = int(data["increment"])
    assert 0 < resumed_from < len(spec["load"])
    subprocess.run([sys.executable, *args], check=True, env=ENV)
    resumed = _history(tmp_path, "killed")
    assert list(resumed.increment) == list(range(1, len(spec["load"]) + 1))
    scale = reference.reaction_force.abs().max()
    np.testing.assert_allclose(resumed.reaction_force, reference.reaction_force, rtol=1e-10, atol=1e-10 * scale)
    np.testing.assert_allclose(resumed.phi_max, reference.phi_max, rtol=1e-10)
    assert not (tmp_path / "killed" / ".work").exists()
    switch = int(reference.increment[reference.phi_max > spec["switch_phi_max"]].iloc[0])
    with h5py.File(tmp_path / "killed" / "fields.h5") as h5:
        # configured increments, the switch-over increment (state for a hybrid run), the last
        assert sorted(h5) == sorted({f"increment_{i:06d}" for i in (40, switch, 70)})
        assert h5.attrs["switch_increment"] == switch


def test_a_run_that_repeats_another_runs_first_increments_starts_from_its_state(quick_config, tmp_path):
    # quick schedule III repeats schedule I's first 20 increments: snt1-III starts from snt1-I's
    # saved state at 20 and must end as the run computed from its first increment (a direct
    # solver: to round-off), with the same rows and the same saved fields
    from ifenn.config import deep_merge, fem_run_spec, shared_prefix
    from ifenn.run_files import read_provenance, read_run_wall, read_states, saved_increments

    config = deep_merge(quick_config, {"solver": {"linear_solvers": "direct"}})
    start = shared_prefix(config, "snt1-III")
    assert start is not None and start["run"] == "snt1-I" and start["increment"] == 20
    assert shared_prefix(deep_merge(config, {"solver": {"share_load_prefix": False}}), "snt1-III") is None
    source, shared = fem_run_spec(config, "snt1-I"), {**fem_run_spec(config, "snt1-III"), "start_from": start}
    mesh = _mesh(source, tmp_path)
    run_fem(source, mesh, tmp_path / "snt1-I", progress=False)
    scratch = fem_run_spec(config, "snt1-III")
    reference = pd.DataFrame(run_fem(scratch, mesh, tmp_path / "scratch", progress=False))
    args = _prepare(shared, tmp_path, "shared")
    missing = subprocess.run([sys.executable, *args], env=ENV, capture_output=True, text=True)
    assert missing.returncode != 0 and "--start-dir" in missing.stderr
    subprocess.run([sys.executable, *args, "--start-dir", str(tmp_path / "snt1-I")], check=True, env=ENV)
    history = _history(tmp_path, "shared")
    assert list(history.increment) == list(range(1, len(scratch["load"]) + 1))
    np.testing.assert_array_equal(history.reaction_force[:20], _history(tmp_path, "snt1-I").reaction_force[:20])
    scale = reference.reaction_force.abs().max()
    assert reference.phi_max.iloc[-1] > 0.99   # the crack ran after the shared increments
    np.testing.assert_allclose(history.reaction_force, reference.reaction_force, rtol=1e-9, atol=1e-9 * scale)
    np.testing.assert_allclose(history.phi_max, reference.phi_max, rtol=1e-9, atol=1e-12)
    fields, expected = tmp_path / "shared" / "fields.h5", tmp_path / "scratch" / "fields.h5"
    assert saved_increments(fields) == saved_increments(expected)
    for ours, theirs in zip(read_states(fields), read_states(expected), strict=True):
        for key in ("phase_field", "displacement", "history"):
            np.testing.assert_allclose(ours[key], theirs[key], rtol=1e-8, atol=1e-10 * np.abs(theirs[key]).max())
    record = read_provenance(tmp_path / "shared")
    assert record["start_from"] == start
    # the run's cost counts the increments it took over (studies compare whole runs)
    assert record["start_wall_s"] == pytest.approx(_history(tmp_path, "snt1-I").t_increment_s[:20].sum())
    assert read_run_wall(tmp_path / "shared") == pytest.approx(record["wall_time_s"] + record["start_wall_s"])
    # a start whose run changed since: refused, naming the run to rerun
    stale = {**shared, "start_from": {**start, "spec_hash": "0000"}}
    with pytest.raises(ValueError, match="rerun snt1-I"):
        run_fem(stale, mesh, tmp_path / "stale", progress=False, start_dir=tmp_path / "snt1-I")


def test_paper_runs_share_only_identical_prefixes(paper_config):
    from ifenn.config import fem_run_spec, paired_runs, shared_prefix

    starts = {run: start for run in paper_config["fem_runs"] if (start := shared_prefix(paper_config, run))}
    assert {run: (s["run"], s["increment"]) for run, s in starts.items()} == {
        "snt1-III": ("snt1-II", 500), "snt1-III-conv": ("snt1-II-conv", 500), "snt1-III-fine": ("snt1-II-fine", 500)}
    for run, start in starts.items():
        mine, theirs = fem_run_spec(paper_config, run), fem_run_spec(paper_config, start["run"])
        assert mine["load"][: start["increment"]] == theirs["load"][: start["increment"]]
        assert mine["load"][start["increment"]] != theirs["load"][start["increment"]]
        assert start["run"] not in starts   # no chains, no cycles
    assert not set(starts) & set(paired_runs(paper_config))


def test_checkpoint_of_another_configuration_is_ignored(quick_spec, tmp_path):
    spec = quick_spec("snt1-I", load=[5e-4 * k for k in range(1, 7)], checkpoint_every=2)
    mesh = _mesh(spec, tmp_path)
    run_fem(spec, mesh, tmp_path / "a", progress=False)
    first = _history(tmp_path, "a")
    (tmp_path / "a" / ".work").mkdir()
    shutil.copy(tmp_path / "a" / "fields.h5", tmp_path / "a" / ".work" / "junk.h5")
    other = {**spec, "material": {**spec["material"], "Gc": 2 * spec["material"]["Gc"]}}
    np.savez(tmp_path / "a" / ".work" / "checkpoint.npz", spec_hash="0000", increment=3)
    rows = run_fem(other, mesh, tmp_path / "a", progress=False)
    assert len(rows) == len(first)


def test_diverging_solve_names_increment_and_reason_and_writes_nothing(quick_spec, quick_config, tmp_path):
    petsc = {**quick_config["solver"]["linear_solver_presets"]["iterative"]}
    petsc["displacement"] = {**petsc["displacement"], "ksp_max_it": 1, "ksp_rtol": 1e-14, "ksp_atol": 1e-30}
    spec = quick_spec("snt1-I", petsc=petsc)
    with pytest.raises(SolverDivergedError, match=r"increment 1 .*displacement solve diverged: KSP_DIVERGED_(ITS|MAX_IT)"):
        run_fem(spec, _mesh(spec, tmp_path), tmp_path / "bad", progress=False)
    assert not (tmp_path / "bad" / "history.csv").exists()
    assert not (tmp_path / "bad" / "fields.h5").exists()


def test_slit_faces_separate_and_the_tip_stays_shared(serial_reference):
    spec, tmp, _ = serial_reference
    mesh = build_mesh(spec["scene"])
    with h5py.File(tmp / "serial" / "fields.h5") as h5:
        u = h5[sorted(h5)[0]]["displacement"][()]
    twins = np.arange(mesh.n_grid_nodes, len(mesh.points))
    originals = np.array([np.flatnonzero(np.all(mesh.points[: mesh.n_grid_nodes] == mesh.points[t], axis=1))[0] for t in twins])
    opening = u[twins, 1] - u[originals, 1]
    assert (opening > 0).all()  # upper face moves up relative to the lower face everywhere
    # opening is largest at the free edge (x = -0.5) and shrinks towards the tip
    order = np.argsort(mesh.points[twins, 0])
    assert opening[order][0] > opening[order][-1] > 0


def test_adaptive_steps_reach_the_fine_schedule_peak_with_fewer_increments(quick_config, tmp_path):
    """Adaptive loading (steps aiming at a phi change of 0.01 per increment, redone when phi moves
    by > 0.02) reaches
    the peak force of a 5x finer fixed schedule within 0.5 %, with fewer increments, where the
    coarse fixed schedule it starts from misses it by more; it ends exactly at u_end."""
    from ifenn.config import fem_run_spec

    spec = fem_run_spec(quick_config, "snt1-I")  # 30 x 5e-4 mm
    mesh = tmp_path / "mesh.xdmf"
    write_mesh(build_mesh(spec["scene"]), mesh)
    fine = {**spec, "name": "fine", "load": [round(1e-4 * (k + 1), 15) for k in range(150)]}
    adaptive = {k: v for k, v in spec.items() if k != "load"}
    adaptive.update(name="adaptive", save_every=10, adaptive={
        "u_end": 0.015, "step_initial": 1e-3, "step_min": 5e-5, "step_max": 1e-3, "phi_change_max": 0.02,
        "quiet_fraction": 0.5, "grow": 4.0, "cut": 0.25})
    runs = {s["name"]: pd.DataFrame(run_fem(s, mesh, tmp_path / s["name"], progress=False)) for s in (fine, adaptive, spec)}
    peak = {name: h.reaction_force.max() for name, h in runs.items()}
    assert abs(peak["adaptive"] / peak["fine"] - 1) < 0.005
    assert abs(peak["snt1-I"] / peak["fine"] - 1) > abs(peak["adaptive"] / peak["fine"] - 1)
    steps = np.diff(np.concatenate([[0.0], runs["adaptive"].u]))
    assert len(runs["adaptive"]) < len(runs["fine"]) and runs["adaptive"].u.iloc[-1] == pytest.approx(0.015)
    assert steps.min() >= 5e-5 * (1 - 1e-9) and steps.max() <= 1e-3 * (1 + 1e-9) and steps.max() > 4 * steps.min()
    assert runs["adaptive"].rejected_steps.sum() > 0  # it did cut and redo increments


def test_crack_advance_ignores_the_diffuse_damage():
    """The adaptive controller's change counts only where phi (before or after) reaches the floor;
    a phi arriving above it counts in full."""
    from ifenn.fem.solver import largest_change

    before = np.array([0.02, 0.05, 0.29, 0.6, 0.9])
    after = np.array([0.06, 0.09, 0.35, 0.61, 0.9])
    assert largest_change(after, before) == pytest.approx(0.06)
    assert largest_change(after, before, floor=0.3) == pytest.approx(0.06)  # 0.29 -> 0.35 crosses the floor
    assert largest_change(after[[0, 1, 3, 4]], before[[0, 1, 3, 4]], floor=0.3) == pytest.approx(0.01)
    assert largest_change(after[:2], before[:2], floor=0.3) == 0.0


def test_an_attempt_stops_early_only_when_the_controller_refuses_it_anyway():
    """refuse_early: past phi_change_max above step_min the attempt is refused whatever its further
    passes do (judge agrees at that change); at step_min, released, or without the setting, never."""
    from ifenn.fem.loading import AdaptiveLoads

    settings = {"u_end": 1.0, "step_initial": 0.1, "step_min": 0.01, "step_max": 0.1, "phi_change_max": 0.02,
                "quiet_fraction": 0.5, "grow": 4.0, "cut": 0.25, "refuse_early": True}
    loads = AdaptiveLoads(settings)
    assert not loads.refuses_early(0.02) and loads.refuses_early(0.021)
    assert loads.judge(0.021, True) is False and loads.du < 0.1
    loads.du = 0.01   # at step_min: always accepted, so never stopped
    assert not loads.refuses_early(1.0) and loads.judge(1.0, True)
    assert not AdaptiveLoads({**settings, "refuse_early": False}).refuses_early(1.0)
    released = AdaptiveLoads(settings)
    released.released = True
    assert not released.refuses_early(1.0)


def test_a_spec_file_its_type_does_not_know_stops_the_job_naming_the_key(quick_config, tmp_path):
    """spec.json is read into its type before anything runs: a misspelled key (or a stale file) stops
    the job with the key named and nothing written; the spec as the config builds it runs."""
    from ifenn.config import fem_run_spec

    spec = fem_run_spec(quick_config, "snt1-I")
    args = _prepare({**spec, "stagger_tolerence": 1e-3}, tmp_path, "typo")
    done = subprocess.run([sys.executable, *args], env=ENV, capture_output=True, text=True)
    assert done.returncode == 2 and "stagger_tolerence" in done.stderr and "typo.json" in done.stderr
    assert not (tmp_path / "typo").exists()
