"""The staggered increment loop (Miehe et al. 2010) with a pluggable phase-field step,
resumable checkpoints and the run's outputs.

Per increment: solve u with the current phi, update H = max(H_prev, psi0+), run the
phase-field step; repeat until max|delta phi| < tol or max_iterations (1 = single pass).

Outputs of a run directory (written atomically, on rank 0; the formats: :mod:`ifenn.run_files`):
  history.csv      one row per increment (HISTORY_COLUMNS)
  fields.h5        the saved increments. The first increment whose phi_max exceeds
                   spec['switch_phi_max'] is always saved (root attr 'switch_increment', -1 if
                   none): a hybrid run starts there.
  paraview.xdmf/.h5  nodal phi and u at the saved increments, for ParaView
  provenance.json  spec hash, versions, ranks, wall time
Work files (resumable state, removed when the run completes): .work/
"""

from __future__ import annotations

import contextlib
import logging
import os
import time
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from mpi4py import MPI

from ifenn import run_files
from ifenn.errors import NonFiniteResultError
from ifenn.fem.loading import largest_change, load_control, load_progress, load_progress_bar
from ifenn.io import provenance
from ifenn.run_files import spec_hash

if TYPE_CHECKING:
    from ifenn.fem.loading import LoadControl
    from ifenn.fem.phase_field import PhaseFieldStep
    from ifenn.fem.problem import FractureProblem

log = logging.getLogger(__name__)

HISTORY_COLUMNS = [
    "increment", "u", "reaction_force", "phi_max", "stagger_iterations",
    "t_displacement_s", "t_phase_field_s", "t_history_s", "t_increment_s",
]


class NodalMap:
    """Local dof blocks of a Q1 space <-> node index of the mesh file (rank-independent)."""

    def __init__(self, space):
        domain = space.mesh
        geometry_dofs = domain.geometry.dofmap.array.reshape(-1, 4)
        input_index = np.asarray(domain.geometry.input_global_indices, dtype=np.int64)[geometry_dofs]
        n_blocks = space.dofmap.index_map.size_local + space.dofmap.index_map.num_ghosts
        self.node_of_block = np.empty(n_blocks, dtype=np.int64)
        self.node_of_block[space.dofmap.list.array.reshape(-1, 4)] = input_index
        self.n_owned = space.dofmap.index_map.size_local
        self.bs = space.dofmap.index_map_bs
        self.comm = domain.comm
        self.n_nodes = self.comm.allreduce(int(self.node_of_block.max(initial=-1)) + 1, op=MPI.MAX)

    def gather(self, function) -> np.ndarray | None:
        """(n_nodes, bs) array on rank 0, None elsewhere."""
        index = self.node_of_block[: self.n_owned]
        values = function.x.array[: self.n_owned * self.bs].reshape(-1, self.bs)
        parts = self.comm.gather((index, values), root=0)
        if self.comm.rank != 0:
            return None
        out = np.zeros((self.n_nodes, self.bs))
        for index, values in parts:
            out[index] = values
        return out

    def scatter(self, array: np.ndarray | None, function) -> None:
        array = self.comm.bcast(array, root=0)
        function.x.array[:] = array[self.node_of_block].ravel()


class Clock:
    """Wall time per named part, summed over the uses of ``with clock(name):``; ``elapsed()``
    is the time since the clock was made."""

    def __init__(self, *names: str):
        self.times = dict.fromkeys(names, 0.0)
        self._start = time.perf_counter()

    @contextlib.contextmanager
    def __call__(self, name: str):
        started = time.perf_counter()
        try:
            yield
        finally:
            self.times[name] += time.perf_counter() - started

    def elapsed(self) -> float:
        return time.perf_counter() - self._start


class StaggeredRun:
    """One run: a problem, a phase-field step, a load list and an output directory."""

    def __init__(self, problem: FractureProblem, phase_field_step: PhaseFieldStep, spec: dict, out_dir: str | Path, progress: bool = True,
                 start: dict | None = None, row_constants: dict | None = None, provenance_extra: dict | None = None):
        """``start``: optional {'increment': k, 'state': state dict (rank 0), 'rows': rows 1..k}
        to continue another run's state (a hybrid run from the FEM switch-over increment).
        ``row_constants``: columns with a fixed value on every computed row.
        ``provenance_extra``: more entries of provenance.json (a hybrid run's switch-over)."""
        self.problem, self.phase_field, self.spec = problem, phase_field_step, spec
        self.start, self.row_constants = start, dict(row_constants or {})
        self.provenance_extra = dict(provenance_extra or {})
        self.loads: LoadControl = load_control(spec)
        adaptive_columns = ["rejected_steps", "rejected_iterations"] if self.loads.adaptive else []
        self.columns = HISTORY_COLUMNS + adaptive_columns + list(phase_field_step.extra_columns) + list(self.row_constants)
        self.out_dir, self.work_dir = Path(out_dir), Path(out_dir) / run_files.WORK
        self.comm = problem.comm
        self.rank0 = self.comm.rank == 0
        self.hash = spec_hash(spec)
        self.progress = progress
        self.u_map, self.phi_map = NodalMap(problem.V), NodalMap(problem.W)
        self.rows: list[dict] = []
        if self.rank0:
            self.work_dir.mkdir(parents=True, exist_ok=True)

    # ------------------------------------------------------------- state
    def _state(self) -> dict | None:
        p = self.problem
        parts = {
            "displacement": self.u_map.gather(p.displacement),
            "phase_field": self.phi_map.gather(p.phase_field),
            "history": p.pixels_from_gauss_points(p.history),
            "phase_field_gp": p.pixels_from_gauss_points(p.phase_field_gp),
        }
        return parts if self.rank0 else None

    def _restore(self, state: dict | None) -> None:
        p = self.problem
        get = (lambda k: state[k]) if self.rank0 else (lambda k: None)
        self.u_map.scatter(get("displacement"), p.displacement)
        self.phi_map.scatter(get("phase_field"), p.phase_field)
        p.gauss_points_from_pixels(get("history"), p.history)
        p.gauss_points_from_pixels(get("phase_field_gp"), p.phase_field_gp)
        p.accept_increment()

    def _resume(self) -> int:
        """Load the checkpoint if it belongs to this spec; returns the last finished increment."""
        path = self.work_dir / "checkpoint.npz"
        found = None
        if self.rank0 and path.exists():
            data = run_files.read_state(path)
            if str(data["spec_hash"]) == self.hash:
                found = data
            else:
                log.warning("ignoring checkpoint of another configuration (%s)", path)
        found_flag = self.comm.bcast(found is not None, root=0)
        if not found_flag:
            if self.start is None:
                return 0
            self._restore(self.start["state"] if self.rank0 else None)
            # rows of the run continued; columns it did not have (this step's extra ones, hybrid_active) are 0
            self.rows = [{**dict.fromkeys(self.columns, 0), **row} for row in self.start["rows"]] if self.rank0 else []
            self.loads.restore({}, self.comm.bcast(self.rows[-2:] if self.rank0 else None, root=0))
            return int(self.start["increment"])
        self._restore(found)
        if self.rank0:
            self.rows = [dict(zip(self.columns, row, strict=True)) for row in found["rows"].tolist()]
            for row in self.rows:
                for key in ("increment", "stagger_iterations", *self.row_constants):
                    row[key] = int(row[key])
            self.loads.restore({k: found[k] for k in self.loads.state() if k in found}, self.rows)
            last = int(found["increment"])
            log.info("resuming %s after increment %d", self.spec["name"], last)
        else:
            last = None
        self.loads.restore(self.comm.bcast(self.loads.state(), root=0), [])
        return self.comm.bcast(last, root=0)

    def _checkpoint(self, increment: int) -> None:
        state = self._state()
        if self.rank0:
            rows = np.array([[row[c] for c in self.columns] for row in self.rows], dtype=float)
            run_files.write_state(self.work_dir / "checkpoint.npz",
                              {**state, **self.loads.state(), "rows": rows, "increment": increment, "spec_hash": self.hash})

    def _snapshot(self, increment: int, u: float) -> None:
        state = self._state()
        if self.rank0:
            run_files.write_state(self.work_dir / f"fields_{increment:06d}.npz", {**state, "u": u, "increment": increment})

    # ------------------------------------------------------------- loop
    def run(self) -> list[dict]:
        """The whole run (or its rest, from a checkpoint): every increment, then the outputs."""
        for _ in self.steps():
            pass
        return self.rows

    def steps(self):
        """The run as a generator: yields each increment's row after its snapshot and checkpoint,
        and writes the outputs after the last. Two runs advanced in turn (``next`` on each) run
        interleaved in one process (:func:`ifenn.studies.drivers.whole_run_benchmark.paired_whole_run`); the wall time in
        provenance.json counts only the time spent in this run's own steps."""
        spec = self.spec
        own_s, started = 0.0, time.perf_counter()
        first = self._resume() + 1
        loads = self.loads
        save = set(spec["save_fields"])
        self.switch_increment = self.comm.bcast(
            next((r["increment"] for r in self.rows if r["phi_max"] > spec["switch_phi_max"]), None), root=0)
        u_previous = self.comm.bcast(self.rows[-1]["u"] if self.rank0 and self.rows else 0.0, root=0)
        bar = load_progress_bar(loads, spec["name"], first, u_previous) if self.rank0 and self.progress else None
        increment = first
        while (u := loads.next_load(increment, u_previous)) is not None:
            try:
                row = self.solve_increment(increment, u, u_previous)
            except Exception as error:
                if bar is not None:
                    bar.close()
                raise type(error)(f"run {spec['name']}, increment {increment} (u = {u:g} mm): {error}") from error
            self.rows.append(row)
            u = row["u"]  # adaptive steps may have cut it
            last = loads.is_last(increment, u)
            if self.switch_increment is None and row["phi_max"] > spec["switch_phi_max"]:
                self.switch_increment = increment
                save.add(increment)
            if increment in save or (spec.get("save_every") and increment % spec["save_every"] == 0) or last:
                self._snapshot(increment, u)
            if increment % spec["checkpoint_every"] == 0 or last:
                self._checkpoint(increment)
            if bar is not None:
                bar.set_postfix(inc=increment, u=f"{u:.4g}", F=f"{row['reaction_force']:.4g}", phi_max=f"{row['phi_max']:.3f}",
                                refresh=False)
                bar.update(load_progress(loads, u, u_previous))
            u_previous, increment = row["u"], increment + 1
            own_s += time.perf_counter() - started
            yield row
            started = time.perf_counter()
        if bar is not None:
            bar.close()
        if self.comm.bcast(self.rank0 and not self._snapshots() and bool(self.rows), root=0):
            # nothing computed (a hybrid run whose switch-over was the last increment): keep the final state
            self._snapshot(self.comm.bcast(self.rows[-1]["increment"] if self.rank0 else None, root=0), u_previous)
        self._finish(own_s + time.perf_counter() - started)

    def solve_increment(self, increment: int, u: float, u_previous: float) -> dict:
        """One load increment at prescribed displacement ``u``: staggered iterations, and with an
        adaptive controller, attempts it refuses undone and redone at its smaller step (their
        time counts). Returns the increment's history row."""
        p, loads = self.problem, self.loads
        clock = Clock("t_displacement_s", "t_history_s", "t_phase_field_s")
        self.phase_field.timings.update(dict.fromkeys(self.phase_field.timings, 0.0))
        accepted = p.snapshot()
        loads.begin_increment()
        rejected_iterations = 0
        while True:
            iterations, converged = self._staggered(u, accepted["phase_field_gp"], clock)
            if not loads.adaptive or loads.judge(self._max_change(p.phase_field_gp.x.array, accepted["phase_field_gp"],
                                                                  loads.phi_floor), converged):
                break
            rejected_iterations += iterations
            p.restore(accepted)
            u = loads.next_load(increment, u_previous)
        p.accept_increment()
        force, phi_max = p.reaction_force(), self.phase_field.phase_field_max()
        if not (np.isfinite(force) and np.isfinite(phi_max)):
            raise NonFiniteResultError(f"non-finite result: reaction force {force}, phi_max {phi_max}")
        adaptive = {"rejected_steps": loads.rejected, "rejected_iterations": rejected_iterations} if loads.adaptive else {}
        return {"increment": increment, "u": u, "reaction_force": force, "phi_max": phi_max, "stagger_iterations": iterations,
                **clock.times, "t_increment_s": clock.elapsed(), **adaptive, **self.phase_field.timings, **self.row_constants}

    def _staggered(self, u: float, phase_field_before: np.ndarray, clock: Clock) -> tuple[int, bool]:
        """Staggered iterations at load ``u`` (Miehe 2010): equilibrium with the current phi,
        then the history, then the phase field, until phi moves by less than the tolerance
        (max norm over the Gauss points) or max_iterations (1: the single pass, converged by
        definition), or until the load controller refuses the attempt already (``refuse_early``).
        Returns (iterations, converged)."""
        p, most = self.problem, self.spec["stagger_max_iterations"]
        previous = phase_field_before
        for iteration in range(1, most + 1):
            with clock("t_displacement_s"):
                p.solve_displacement(u)
            with clock("t_history_s"):
                p.update_history()
            with clock("t_phase_field_s"):
                self.phase_field.solve()
            if self._max_change(p.phase_field_gp.x.array, previous) < self.spec["stagger_tolerance"]:
                return iteration, True
            if iteration < most and self.loads.adaptive:   # refused whatever the remaining passes do (AdaptiveLoads)
                moved = self._max_change(p.phase_field_gp.x.array, phase_field_before, self.loads.phi_floor)
                if self.loads.refuses_early(moved):
                    return iteration, False
            previous = p.phase_field_gp.x.array.copy()
        return most, most == 1

    def _max_change(self, a: np.ndarray, b: np.ndarray, floor: float = 0.0) -> float:
        return self.comm.allreduce(largest_change(a, b, floor), op=MPI.MAX)

    # ------------------------------------------------------------- outputs
    def _finish(self, wall_s: float) -> None:
        self._write_paraview()
        if self.rank0:
            import pandas as pd

            self._write_fields()
            run_files.write_history(self.out_dir, pd.DataFrame(self.rows, columns=self.columns))
            run_files.write_provenance(self.out_dir, provenance(
                self.hash, wall_s, run=self.spec["name"], mpi_ranks=self.comm.size,
                phase_field_step=self.phase_field.name, increments=len(self.rows), **self.provenance_extra))
            for path in self.work_dir.glob("*"):
                path.unlink()
            self.work_dir.rmdir()
        self.comm.barrier()

    def _snapshots(self) -> list[Path]:
        return sorted(self.work_dir.glob("fields_*.npz"))

    def _write_fields(self) -> None:
        def states():
            for path in self._snapshots():
                data = run_files.read_state(path)
                yield {key: data[key] for key in ("increment", "u", *run_files.FIELD_KEYS)}

        attrs = {**self.problem.pixels.attrs(), "run": self.spec["name"], "spec_hash": self.hash,
                 "switch_increment": self.switch_increment or -1}
        run_files.write_fields(self.out_dir / run_files.FIELDS, attrs, states())

    def _write_paraview(self) -> None:
        """XDMF of nodal phi and u at the saved increments (time = u), written in a temporary
        folder and moved, so the pair appears complete."""
        from dolfinx import io

        snapshots = self.comm.bcast([str(s) for s in self._snapshots()] if self.rank0 else None, root=0)
        tmp_dir = self.work_dir / "paraview"
        if self.rank0:
            tmp_dir.mkdir(parents=True, exist_ok=True)
        self.comm.barrier()
        p = self.problem
        with io.XDMFFile(self.comm, str(tmp_dir / "paraview.xdmf"), "w") as xdmf:
            xdmf.write_mesh(p.domain)
            for path in snapshots:
                data = run_files.read_state(path) if self.rank0 else None
                self.u_map.scatter(data["displacement"] if data else None, p.displacement)
                self.phi_map.scatter(data["phase_field"] if data else None, p.phase_field)
                u = self.comm.bcast(float(data["u"]) if data else None, root=0)
                xdmf.write_function(p.displacement, u)
                xdmf.write_function(p.phase_field, u)
        self.comm.barrier()
        if self.rank0:
            for name in ("paraview.h5", "paraview.xdmf"):
                os.replace(tmp_dir / name, self.out_dir / name)
            tmp_dir.rmdir()


def fem_run(spec: dict, mesh_path: str | Path, out_dir: str | Path, progress: bool = True,
            start_dir: str | Path | None = None) -> StaggeredRun:
    """The plain-FEM run described by ``spec`` (config.fem_run_spec), set up, not started; the
    caller holds ``out_dir``'s lock (:func:`ifenn.run_files.exclusive_writer`). With
    ``start_from`` in the spec it continues the state of the run in ``start_dir``
    (:func:`ifenn.run_files.take_over`)."""
    from ifenn.fem.mesh import read_dolfinx_mesh
    from ifenn.fem.phase_field import FEMPhaseField
    from ifenn.fem.problem import FractureProblem

    comm = MPI.COMM_WORLD
    start = None
    if spec.get("start_from") is not None:   # the first increments another run computed (run_files.take_over)
        start = {"increment": int(spec["start_from"]["increment"]), "state": None, "rows": None}
        if comm.rank == 0:
            if start_dir is None:
                raise ValueError(f"run {spec['name']} starts from run {spec['start_from']['run']}'s saved state: "
                                 "its output directory is needed (--start-dir)")
            state, start["rows"] = run_files.take_over(spec["start_from"], start_dir, Path(out_dir) / run_files.WORK,
                                                       spec["save_fields"])
            start["state"] = {key: state[key] for key in run_files.FIELD_KEYS}
            log.info("%s starts from %s's increment %d", spec["name"], spec["start_from"]["run"], start["increment"])
    domain = read_dolfinx_mesh(mesh_path, comm)
    problem = FractureProblem(domain, spec["scene"], spec["material"], spec["petsc"], comm)
    # the increments taken over count in the run's cost (studies compare whole runs)
    provenance_extra = {"start_from": spec["start_from"],
                        "start_wall_s": float(sum(row["t_increment_s"] for row in start["rows"])) if comm.rank == 0 else None
                        } if start is not None else None
    return StaggeredRun(problem, FEMPhaseField(problem, spec["petsc"]["phase_field"]), spec, out_dir, progress, start=start,
                        provenance_extra=provenance_extra)


def run_fem(spec: dict, mesh_path: str | Path, out_dir: str | Path, progress: bool = True,
            start_dir: str | Path | None = None) -> list[dict]:
    """Run a plain-FEM phase-field analysis described by ``spec`` (config.fem_run_spec;
    ``start_dir``: the run it starts from, when the spec has ``start_from``)."""
    with run_files.exclusive_writer(out_dir, MPI.COMM_WORLD):
        return fem_run(spec, mesh_path, out_dir, progress, start_dir).run()
