"""A run whose displacement mesh follows the crack: the state on the pixel grid, the mesh rebuilt
from it when the crack leaves the fine region, and the increment then redone or continued.

Per increment (single pass, or staggered to a tolerance as the FEM runs):

1. u on the current mesh with phi of the last increment at its Gauss points
   (:class:`ifenn.adaptive.problem.AdaptiveMeshProblem`);
2. H = max(H of the last increment, psi_0^+(u)) at every pixel centre;
3. phi from the pixel equation (Gc/lc + 2H) phi - Gc lc Lap9(phi) = 2H on the whole image, the
   slits' links cut, solved by the multigrid-preconditioned CG of the verified step
   (:meth:`ifenn.pixel_equation.numpy_backend.PixelEquation.solve_box`) from the last increment's phi, to
   max |phi - exact pixel solution| <= ``phase_field_tolerance`` (the residual certificate); a
   verified IFENN run (a spec with ``verification`` enabled) instead takes the network's
   prediction on the capped H, checks it and corrects it where it fails
   (:class:`ifenn.hybrid.verification.VerifiedInference`, to its tolerance): the same equation;
4. predictor-corrector: the crack core (:func:`crack_core`) grown by ``trigger_lc`` must lie in the
   finest leaves; if it does not, the fine region grows by the new core and its buffer and the mesh
   is rebuilt (at most ``max_remesh`` times an increment; a run that still leaves the region is
   reported in the row's ``outside_fine`` column, never silently). A single pass looks after the
   pass and is redone from the last increment's images. Staggering to convergence looks after every
   pass and goes on from its current phi on the new mesh, with at least one more pass there
   (``staggered_remesh: continue``; phi lives on the pixels, so nothing is lost, and every pass
   solved u with the tip inside fine cells, since the trigger fires at trigger_lc < buffer_lc). Redone
   from the start instead (``redo``), a drop increment at the 50-pass cap cost 100 passes: measured
   on snt1-A-conv-adaptive, 500 of its 1,152 displacement solves were passes thrown away.

The refinement criterion (config ``adaptive_mesh``; reasoning here): the crack's core is where
phi >= ``mark_phi`` (the crack and its process zone), or where the local phase field of the
current tensile energy, 2 psi+ / (Gc/lc + 2 psi+), >= ``mark_energy_phi``: the tip's stress
concentration, flagged increments before phi follows, so that H (a max over the past) is never
taken from a coarse cell at the tip. The current energy, not H: H keeps the swept tip zones, and
on snt1-II the fine region then grew to a band 0.56 mm high around the crack (53 % of the finer
mesh's dofs at the end, measured), where u needs no fine cells once the tip has passed; phi and H
live on the pixels whatever the mesh. The threshold 0.2 sits below AT2's homogeneous critical
damage (1/4: a uniform bar softens and localises from there) and above the far field of a specimen
under a high nominal stress, which needs no fine cells (u is smooth there; its diffuse damage lives
on the pixels). Measured at the paper's scale: ahead of snt1's notch the ligament reaches ~0.05
before the peak; sdnt's ligament 0.08-0.10 over half the image (at 0.1 the fine region took 85 % of
the finer mesh's dofs by the end, mean 22.6 %, 353 s; at 0.2: 29 %, mean 7.0 %, 108 s, the same peak
to 0.03 %, post-peak RMS 0.94 % of the peak apart). snt1-II at 0.2 against 0.1: peak 0.04 % apart,
post-peak RMS 0.17 %, mean dofs 5.6 against 9.4 % of the finer mesh's, 80 against 137 s. Corners where a held edge meets a free one are
marked too (their energy is singular, as at a tip, and AT2 damages them). mark_phi 0.5 with a
buffer of 2 lc (trigger 1 lc) against 0.2 with 3 lc (1.5 lc), snt1-II at the paper's scale: the
same curve (0.11 % of the peak apart at most; post-peak RMS against the finer uniform FEM 0.39 and
0.38 %, peak +0.18 and +0.19 %) on 30 % fewer dofs (mean 9.4 against 13.5 % of the finer mesh's).

The mesh is built fine on the core grown by ``buffer_lc`` phase-field lengths, and rebuilt when
the core grown by ``trigger_lc`` (< buffer_lc) leaves the finest leaves: the crack advances
buffer_lc - trigger_lc before the mesh must follow (a hysteresis: the finer mesh resolves the
tip better, raises the energy there and grows the core, and without the gap each rebuild would
ask for another). A rebuild makes the mesh fine on the last accepted increment's region and on
what the attempts of this increment marked, so it coarsens behind the tip (where phi < mark_phi
and the energy has dropped); the mesh never coarsens where phi >= mark_phi. The 2:1 grading does
the rest.

Outputs, as a FEM run's (:mod:`ifenn.run_files`): history.csv (with ``dofs``, ``cells``,
``remeshes`` per increment), fields.h5 (pixel images: ``history``, ``phase_field_gp`` = phi,
``phase_field`` = phi flattened, ``displacement`` = u at the pixel centres, and ``leaf_level`` of
the fine cells: the mesh), provenance.json. The checkpoint holds the two images and the marked
regions, not the mesh: a resumed run rebuilds it.

Two regions are kept: ``region``, the last accepted increment's fine region (the one a rebuild
starts from), and ``mesh_region``, the one the current mesh was built from, which also
holds what a refused attempt marked. An attempt on a mesh too coarse at a new tip can mark
pixels the redone increment does not (a coarse cell's energy is not the fine one's); those stay
fine until the next rebuild only.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ifenn import geometry, run_files
from ifenn.adaptive.quadtree import FineSlit, Quadtree, build_quadtree, pad, padded_shape
from ifenn.device import device_record, network_device
from ifenn.errors import NonFiniteResultError
from ifenn.fem import supports
from ifenn.fem.loading import largest_change, load_control, load_progress, load_progress_bar
from ifenn.io import provenance
from ifenn.pixels import PixelGrid, SlitCuts
from ifenn.run_files import spec_hash

log = logging.getLogger(__name__)

COLUMNS = ["increment", "u", "reaction_force", "phi_max", "stagger_iterations", "t_displacement_s", "t_phase_field_s",
           "t_history_s", "t_remesh_s", "t_increment_s", "dofs", "cells", "remeshes", "outside_fine", "phase_field_iterations",
           "t_network_s", "verify_residual_after", "displacement_iterations", "displacement_solves", "rejected_steps",
           "rejected_iterations"]
#: integer columns (a checkpoint stores the rows as floats)
INTEGER_COLUMNS = ("increment", "stagger_iterations", "dofs", "cells", "remeshes", "outside_fine", "phase_field_iterations",
                   "displacement_iterations", "displacement_solves", "rejected_steps", "rejected_iterations")


@dataclass(frozen=True)
class MeshSettings:
    """config ``adaptive_mesh`` (module doc)."""

    levels: int = 3                     # the coarsest leaf is 2^levels fine cells wide
    pixels_per_fine_cell: int = 1       # 1: the fine cells are the pixels (h/2 of the scene's elements)
    mark_phi: float = 0.5
    mark_energy_phi: float = 0.2
    buffer_lc: float = 2.0
    trigger_lc: float = 1.0
    phase_field_tolerance: float = 1e-6
    max_remesh: int = 6
    linear_solvers: str = "direct"      # the displacement solve's preset (config.adaptive_run_spec applies it)
    staggered_remesh: str = "continue"  # staggering to convergence goes on from its phi on a rebuilt mesh (or: redo)

    @classmethod
    def from_spec(cls, spec: dict) -> MeshSettings:
        return cls(**spec.get("adaptive_mesh", {}))


def fine_layout(scene: dict, grid: PixelGrid, settings: MeshSettings) -> tuple[int, tuple[int, int], np.ndarray | None]:
    """The quadtree's levels, the fine grid it is built on (the scene's, grown at the top and right
    to whole coarsest blocks: :func:`ifenn.adaptive.quadtree.padded_shape`) and the fine cells left
    out of every mesh (the scene's cut-outs, ifenn.geometry, and that padding; None if none)."""
    p = settings.pixels_per_fine_cell
    ny, nx = grid.ny_px // p, grid.nx_px // p
    shape = padded_shape(ny, nx, settings.levels)
    removed = None
    if scene.get("cutouts"):
        removed = ~geometry.solid_pixels(scene, PixelGrid(grid.x0, grid.y0, grid.h_px * p, nx, ny))
    if shape != (ny, nx) or removed is not None:
        removed = pad(np.zeros((ny, nx), dtype=bool) if removed is None else removed, shape, True)
    return settings.levels, shape, removed


def fine_slits(scene: dict, h_fine: float) -> list[FineSlit]:
    """The scene's slits on its element grid (moved to the nearest line where a slit says
    ``snap: true``), as the uniform mesh's
    (:func:`ifenn.fem.mesh.build_mesh`), in fine-cell units."""
    from ifenn.fem.mesh import element_size, grid_line

    h = element_size(scene)
    factor = int(round(h / h_fine))
    if abs(h / h_fine - factor) > 1e-9:
        raise ValueError(f"the scene's elements ({h:g} mm) must be a whole number of fine cells ({h_fine:g} mm)")
    x0, y0 = scene["domain"]["x"][0], scene["domain"]["y"][0]
    nx, ny = scene["elements"]
    out = []
    for notch in scene.get("notches", []):
        if notch["kind"] != "slit":
            continue
        (sx, sy), (ex, ey) = notch["start"], notch["end"]
        if abs(sy - ey) <= abs(sx - ex):
            a, b = sorted((grid_line(sx, x0, h, nx), grid_line(ex, x0, h, nx)))
            out.append(FineSlit(0, factor * grid_line(sy, y0, h, ny), factor * a, factor * b))
        else:
            a, b = sorted((grid_line(sy, y0, h, ny), grid_line(ey, y0, h, ny)))
            out.append(FineSlit(1, factor * grid_line(sx, x0, h, nx), factor * a, factor * b))
    return out


def initial_history(scene: dict, material: dict, grid: PixelGrid) -> np.ndarray:
    """H0 of the scene's history notches at the pixel centres (as the uniform FEM's at its
    Gauss points, :meth:`ifenn.fem.problem.FractureProblem.set_initial_history`)."""
    from ifenn.fem.problem import distance_to_segment

    notches = [n for n in scene.get("notches", []) if n["kind"] == "history"]
    if not notches:
        return np.zeros(grid.shape)
    from ifenn.models import phase_field_model

    xc, yc = grid.pixel_centres()
    points = np.stack(np.meshgrid(xc, yc), axis=-1).reshape(-1, 2)
    distance = np.min([distance_to_segment(points, n["start"], n["end"]) for n in notches], axis=0)
    return phase_field_model(material).notch_history(distance, material).reshape(grid.shape)


def crack_core(phi: np.ndarray, energy: np.ndarray, material: dict, settings: MeshSettings) -> np.ndarray:
    """The pixels of the crack and of the tip's stress concentration (module doc): ``energy`` is
    the tensile energy psi_0^+ of the current displacement, not its max over the past."""
    local = 2.0 * energy / (material["Gc"] / material["lc"] + 2.0 * energy)
    return (phi >= settings.mark_phi) | (local >= settings.mark_energy_phi)


def grown(core: np.ndarray, by_lc: float, material: dict, h_px: float) -> np.ndarray:
    """``core`` grown by ``by_lc`` phase-field lengths (a square of that half-width), filtered on
    the core's bounding box only (:func:`ifenn.pixel_equation.numpy_backend.dilated`: the whole-image filter
    was 11 % of an increment on an 800 x 800 image)."""
    from ifenn.pixel_equation.numpy_backend import dilated

    return dilated(core, int(np.ceil(by_lc * material["lc"] / h_px)))


def _typed(rows: list[dict]) -> list[dict]:
    """History rows read back (a checkpoint's floats, a CSV's numpy numbers) with their integer columns as int."""
    for row in rows:
        for key in INTEGER_COLUMNS:
            row[key] = int(row[key])
    return rows


class AdaptiveRun:
    """One run on a displacement mesh that follows the crack (module doc)."""

    def __init__(self, spec: dict, out_dir: str | Path, progress: bool = True, model_path: str | Path | None = None,
                 device="auto", start_dir: str | Path | None = None):
        from ifenn.pixel_equation.numpy_backend import PixelEquation

        self.spec, self.out_dir = spec, Path(out_dir)
        self.work_dir = self.out_dir / run_files.WORK
        self.settings = MeshSettings.from_spec(spec)
        self.scene, self.material = spec["scene"], spec["material"]
        self.grid = PixelGrid.for_scene(self.scene)
        self.h_fine = self.grid.h_px * self.settings.pixels_per_fine_cell
        p = self.settings.pixels_per_fine_cell
        if self.grid.nx_px % p or self.grid.ny_px % p:
            raise ValueError(f"adaptive_mesh.pixels_per_fine_cell = {p} must divide the pixel grid {self.grid.shape}")
        self.n_fine = (self.grid.ny_px // p, self.grid.nx_px // p)
        self.levels, self.n_padded, self.removed = fine_layout(self.scene, self.grid, self.settings)
        self.slits = fine_slits(self.scene, self.h_fine)
        Gc, lc = self.material["Gc"], self.material["lc"]
        self.equation = PixelEquation(Gc, lc, self.grid.h_px, "replicate", SlitCuts.for_scene(self.scene, self.grid))
        self.loads = load_control(spec)   # fixed, or adaptive steps (ifenn.fem.loading.AdaptiveLoads, as FEM's)
        self.progress, self.hash = progress, spec_hash(spec)
        self.start_dir = start_dir
        if spec.get("start_from") is not None and start_dir is None:
            raise ValueError(f"run {spec['name']} starts from run {spec['start_from']['run']}'s increment "
                             f"{spec['start_from']['increment']}: its output directory is needed (--start-dir)")
        self.rows: list[dict] = []
        self.history = initial_history(self.scene, self.material, self.grid)
        self.phi = np.zeros(self.grid.shape)
        self.region = self.mesh_region = self._fine_region(self.phi, self.history)   # H0: a history notch's tip
        self.problem = None
        self.verified = None
        self.device = None
        if (spec.get("verification") or {}).get("enabled"):
            from ifenn.hybrid.runs import make_inference

            if model_path is None:
                raise ValueError(f"run {spec['name']} is a verified IFENN run: it needs the trained network (model_path)")
            self.device = network_device(spec, device)
            self.verified = make_inference(spec, model_path, self.grid.h_px, self.grid.shape, self.device)

    def _phase_field(self, phi: np.ndarray, history: np.ndarray) -> tuple[np.ndarray, int, float, float]:
        """The phase field of ``history`` (module doc, step 3): the certified pixel solve from
        ``phi`` (in place), or the verified IFENN step (network, check, correction; on the capped H
        unless its cap_history is off). Returns (phi, CG iterations, network seconds, max |r| after)."""
        if self.verified is None:
            worst, iterations = self.equation.solve_box(phi, history, (slice(0, phi.shape[0]), slice(0, phi.shape[1])),
                                                        self.settings.phase_field_tolerance)
            return phi, iterations, 0.0, worst
        step = self.verified
        step.start_from(phi)
        phi = step(np.maximum(history, 0.0))   # capped by the step: for the network, for its equation unless cap_history is off
        return phi.copy(), step.solve_iterations, step.t_network, step.residual_after

    # ------------------------------------------------------------------ mesh
    def _fine_region(self, phi: np.ndarray, energy: np.ndarray, by_lc: float | None = None) -> np.ndarray:
        core = crack_core(phi, energy, self.material, self.settings)
        return grown(core, self.settings.buffer_lc if by_lc is None else by_lc, self.material, self.grid.h_px)

    def _target(self, region: np.ndarray) -> np.ndarray:
        """Fine-cell target levels: the finest where a fine cell holds a marked pixel."""
        p = self.settings.pixels_per_fine_cell
        ny, nx = self.n_fine
        fine = region.reshape(ny, p, nx, p).any(axis=(1, 3))
        fine |= supports.anchor_cells(self.scene, (self.grid.x0, self.grid.y0), self.h_fine, (ny, nx))
        return pad(np.where(fine, self.levels, 0), self.n_padded, 0)

    def build_mesh(self, region: np.ndarray) -> None:
        from ifenn.adaptive.problem import AdaptiveMeshProblem, transfer_displacement

        self.mesh_region = region
        tree = build_quadtree(self._target(region), self.levels, (self.grid.x0, self.grid.y0), self.h_fine, self.slits,
                              self.removed)
        petsc = self.spec["petsc"]
        old, self.problem = self.problem, AdaptiveMeshProblem(tree, self.scene, self.material, petsc["displacement"], self.grid,
                                                              petsc.get("displacement_reuse"), petsc.get("displacement_matrix", "aij"))
        if old is not None:   # the solve on the new mesh starts from the old solution
            transfer_displacement(old, self.problem)

    def inside_fine(self, marked: np.ndarray) -> bool:
        """Whether every marked pixel lies in a finest leaf."""
        tree: Quadtree = self.problem.tree
        p = self.settings.pixels_per_fine_cell
        ny, nx = self.n_fine
        finest = np.repeat(np.repeat(tree.leaf_level[:ny, :nx] == self.levels, p, axis=0), p, axis=1)
        return bool(finest[marked].all())

    # ------------------------------------------------------------------ state
    def _checkpoint(self, increment: int) -> None:
        rows = np.array([[row[c] for c in COLUMNS] for row in self.rows], dtype=float)
        run_files.write_state(self.work_dir / "checkpoint.npz", {"history": self.history, "phase_field": self.phi, "region": self.region,
                                                                 "mesh_region": self.mesh_region, **self.loads.state(),
                                                                 "rows": rows, "increment": increment, "spec_hash": self.hash})

    def _start(self) -> int:
        """The state of the run this one continues (spec ``start_from``,
        :func:`ifenn.config.adaptive_shared_prefix`, :func:`ifenn.run_files.take_over`) at its
        increment k and its rows 1..k; returns k (0 without ``start_from``)."""
        start = self.spec.get("start_from")
        if start is None:
            return 0
        state, rows = run_files.take_over(start, self.start_dir, self.work_dir, self.spec["save_fields"],
                                          keys=(*run_files.FIELD_KEYS, *run_files.OPTIONAL_KEYS))
        self.history, self.phi = state["history"], state["phase_field_gp"]
        self.region, self.mesh_region = state["region"].astype(bool), state["mesh_region"].astype(bool)
        self.rows = _typed(rows)
        log.info("%s starts from %s's increment %d", self.spec["name"], start["run"], state["increment"])
        return int(state["increment"])

    def _resume(self) -> int:
        path = self.work_dir / "checkpoint.npz"
        if not path.exists():
            return self._start()
        data = run_files.read_state(path)
        if str(data["spec_hash"]) != self.hash or data["rows"].shape[-1] != len(COLUMNS):
            log.warning("ignoring checkpoint of another configuration or version (%s)", path)
            return self._start()
        self.history, self.phi = data["history"], data["phase_field"]
        self.region, self.mesh_region = data["region"].astype(bool), data["mesh_region"].astype(bool)
        self.rows = _typed([dict(zip(COLUMNS, row, strict=True)) for row in data["rows"].tolist()])
        self.loads.restore({k: data[k] for k in self.loads.state() if k in data}, self.rows)
        log.info("resuming %s after increment %d", self.spec["name"], int(data["increment"]))
        return int(data["increment"])

    def _snapshot(self, increment: int, u: float) -> None:
        problem = self.problem
        run_files.write_state(self.work_dir / f"fields_{increment:06d}.npz", {
            "increment": increment, "u": u, "history": self.history, "phase_field_gp": self.phi, "phase_field": self.phi.ravel(),
            "displacement": problem.displacement_at_pixels(), "leaf_level": problem.tree.leaf_level[: self.n_fine[0], : self.n_fine[1]],
            "region": self.region, "mesh_region": self.mesh_region})

    # ------------------------------------------------------------------ loop
    def run(self) -> list[dict]:
        started = time.perf_counter()
        self.work_dir.mkdir(parents=True, exist_ok=True)
        first = self._resume() + 1
        self.build_mesh(self.mesh_region)
        save = set(self.spec["save_fields"])
        every = self.spec.get("save_every")   # adaptive steps: fields every save_every increments
        u_previous = self.rows[-1]["u"] if self.rows else 0.0
        bar = load_progress_bar(self.loads, self.spec["name"], first, u_previous) if self.progress else None
        increment = first
        while (u := self.loads.next_load(increment, u_previous)) is not None:
            try:
                row = self.solve_increment(increment, u, u_previous)
            except Exception as error:
                if bar is not None:
                    bar.close()
                raise type(error)(f"run {self.spec['name']}, increment {increment} (u = {u:g} mm): {error}") from error
            self.rows.append(row)
            u = row["u"]   # adaptive steps may have cut it
            last = self.loads.is_last(increment, u)
            if increment in save or (every and increment % every == 0) or last:
                self._snapshot(increment, u)
            if increment % self.spec["checkpoint_every"] == 0 or last:
                self._checkpoint(increment)
            if bar is not None:
                bar.set_postfix(F=f"{row['reaction_force']:.4g}", phi_max=f"{row['phi_max']:.3f}", dofs=row["dofs"], refresh=False)
                bar.update(load_progress(self.loads, u, u_previous))
            u_previous, increment = u, increment + 1
        if bar is not None:
            bar.close()
        self._finish(time.perf_counter() - started)
        return self.rows

    def solve_increment(self, increment: int, u: float, u_previous: float = 0.0) -> dict:
        """One increment at prescribed displacement ``u``, redone on a new mesh while the crack
        leaves the fine region (module doc); with adaptive steps, an attempt the controller refuses
        (phi moved too far, or the staggering did not converge) is undone and redone at its smaller
        step, as FEM's (:class:`ifenn.fem.loading.AdaptiveLoads`; every attempt's time counts).
        Returns its history row."""
        loads = self.loads
        loads.begin_increment()
        times = dict.fromkeys(("t_displacement_s", "t_phase_field_s", "t_history_s", "t_remesh_s"), 0.0)
        counts = {"remeshes": 0, "phase_field_iterations": 0, "displacement_iterations": 0, "displacement_solves": 0, "t_network_s": 0.0}
        started = time.perf_counter()
        rejected_iterations = 0
        while True:
            row, history, phi, converged, region = self._attempt(u, times, counts)
            if not loads.adaptive or loads.judge(largest_change(phi, self.phi, loads.phi_floor), converged):
                break
            rejected_iterations += row["stagger_iterations"]
            u = loads.next_load(increment, u_previous)   # the state is still the last accepted one: redo
        self.history, self.phi, self.region = history, phi, region
        return {"increment": increment, "u": u, **row, **times, "t_increment_s": time.perf_counter() - started, **counts,
                "rejected_steps": loads.rejected if loads.adaptive else 0, "rejected_iterations": rejected_iterations}

    def _attempt(self, u: float, times: dict, counts: dict):
        """Staggered iterations at ``u`` from the last accepted state, the mesh rebuilt when the
        crack leaves its fine cells (module doc, step 4). Returns (the row's values, H, phi,
        converged, the next fine region); ``times`` and ``counts`` accumulate. The accepted state
        (``self.phi``, ``self.history``, ``self.region``) is not touched."""
        settings, spec = self.settings, self.spec
        most = spec["stagger_max_iterations"]
        # staggering to convergence looks at the fine region after every pass and goes on from its
        # current phi on a rebuilt mesh; a single pass (or staggered_remesh: redo) is redone from
        # the accepted state
        carry_on = most > 1 and settings.staggered_remesh == "continue"
        remeshes, pending = 0, self.region          # what this increment's rebuilds ask for (module doc)
        problem = self.problem
        problem.set_phase_field(self.phi)
        phi = self.phi.copy()
        iteration, last = 0, most
        while True:
            iteration += 1
            t = time.perf_counter()
            counts["displacement_iterations"] += problem.solve_displacement(u)
            counts["displacement_solves"] += 1
            times["t_displacement_s"] += time.perf_counter() - t
            t = time.perf_counter()
            energy = problem.tensile_energy()
            history = np.maximum(self.history, energy)
            times["t_history_s"] += time.perf_counter() - t
            t = time.perf_counter()
            before = phi.copy()
            phi, iterations, t_network, residual_after = self._phase_field(phi, history)
            counts["phase_field_iterations"] += iterations
            counts["t_network_s"] += t_network
            problem.set_phase_field(phi)
            times["t_phase_field_s"] += time.perf_counter() - t
            converged = most == 1 or np.abs(phi - before).max() < spec["stagger_tolerance"]   # one pass: converged by definition
            # refused already (AdaptiveLoads.refuse_early): the remaining passes would be thrown away
            refused = (not converged and self.loads.adaptive
                       and self.loads.refuses_early(largest_change(phi, self.phi, self.loads.phi_floor)))
            done = converged or refused or iteration >= last
            if not (done or carry_on):
                continue
            t = time.perf_counter()
            core = crack_core(phi, energy, self.material, settings)
            outside = not self.inside_fine(grown(core, settings.trigger_lc, self.material, self.grid.h_px))
            if outside and remeshes < settings.max_remesh and not refused:
                pending = pending | grown(core, settings.buffer_lc, self.material, self.grid.h_px)
                self.build_mesh(pending)
                remeshes += 1
                counts["remeshes"] += 1
                problem = self.problem
                if carry_on:   # at least one more pass, on the new mesh
                    problem.set_phase_field(phi)
                    last = max(most, iteration + 1)
                else:
                    problem.set_phase_field(self.phi)
                    phi, iteration = self.phi.copy(), 0
                times["t_remesh_s"] += time.perf_counter() - t
                continue
            times["t_remesh_s"] += time.perf_counter() - t
            if done:
                break
        force = problem.reaction_force()
        if not np.isfinite(force):
            raise NonFiniteResultError(f"non-finite reaction force {force}")
        row = {"reaction_force": force, "phi_max": float(phi.max()), "stagger_iterations": iteration, "dofs": problem.n_dofs,
               "cells": problem.tree.n_cells, "outside_fine": int(outside), "verify_residual_after": residual_after}
        return row, history, phi, converged, grown(core, settings.buffer_lc, self.material, self.grid.h_px)

    # ------------------------------------------------------------------ outputs
    def _finish(self, wall_s: float) -> None:
        import pandas as pd

        def states():
            for path in sorted(self.work_dir.glob("fields_*.npz")):
                yield run_files.read_state(path)

        attrs = {**self.grid.attrs(), "run": self.spec["name"], "spec_hash": self.hash, "switch_increment": -1}
        run_files.write_fields(self.out_dir / run_files.FIELDS, attrs, states())
        run_files.write_history(self.out_dir, pd.DataFrame(self.rows, columns=COLUMNS))
        extra = {}
        if self.spec.get("start_from") is not None:   # the increments taken over count in the run's cost
            k = int(self.spec["start_from"]["increment"])
            extra = {"start_from": self.spec["start_from"], "start_wall_s": float(sum(r["t_increment_s"] for r in self.rows[:k]))}
        run_files.write_provenance(self.out_dir, provenance(self.hash, wall_s, run=self.spec["name"], mpi_ranks=1,
                                                           phase_field_step="verified" if self.verified else "pixel-exact", increments=len(self.rows),
                                                           displacement_mesh="adaptive", **device_record(self.device), **extra))
        for path in self.work_dir.glob("*"):
            path.unlink()
        self.work_dir.rmdir()


def run_adaptive(spec: dict, out_dir: str | Path, progress: bool = True, model_path: str | Path | None = None,
                 device="auto", start_dir: str | Path | None = None) -> list[dict]:
    """Run ``spec`` (:func:`ifenn.config.adaptive_run_spec`) on a mesh that follows the crack,
    with the trained network at ``model_path`` for a verified IFENN run; one process at a time
    writes ``out_dir``. ``start_dir``: the run it starts from, when the spec has ``start_from``."""
    from mpi4py import MPI

    if MPI.COMM_WORLD.size > 1:
        raise RuntimeError("adaptive-mesh runs are serial: start them on one process")
    with run_files.exclusive_writer(out_dir, MPI.COMM_WORLD):
        return AdaptiveRun(spec, out_dir, progress, model_path, device, start_dir).run()
