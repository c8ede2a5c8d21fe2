"""The discrete fracture problem on dolfinx 0.5.2: spaces, fields, boundary conditions,
the equilibrium solve, the history update and the reaction force.

Everything (forms, matrices, solvers, expressions) is built once per run; the increment
loop in ``solver.py`` only reassembles and solves. Gauss-point fields (history H and the
phase field used in the degradation) live in a Quadrature space with 2x2 points.
"""

from __future__ import annotations

import contextlib

import basix
import numpy as np
import ufl
from dolfinx import cpp as dcpp
from dolfinx import fem, jit, la
from dolfinx import mesh as dmesh
from dolfinx.fem import petsc as fem_petsc
from mpi4py import MPI
from petsc4py import PETSc

from ifenn import geometry
from ifenn.errors import SolverDivergedError  # noqa: F401 (raised here; importers take it from here too)
from ifenn.fem import supports
from ifenn.models import phase_field_model
from ifenn.pixels import PixelGrid

QUADRATURE = {"quadrature_degree": 2, "quadrature_scheme": "default"}
EDGE_COMPONENT = {"x": 0, "y": 1}


_REASONS = {getattr(PETSc.KSP.ConvergedReason, k): k for k in dir(PETSc.KSP.ConvergedReason) if not k.startswith("_")}


def configure_ksp(ksp: PETSc.KSP, prefix: str, options: dict) -> None:
    """Apply a dictionary of PETSc options under ``prefix`` (the one place solvers are set)."""
    ksp.setOptionsPrefix(prefix)
    with petsc_options(prefix, options):
        ksp.setFromOptions()


@contextlib.contextmanager
def petsc_options(prefix: str, options: dict):
    """PETSc's options database holds ``options`` under ``prefix`` inside the block only.
    Options read when a preconditioner is set up (GAMG's ``mg_levels_*`` smoothers) need them
    there during that set-up, not only during setFromOptions."""
    opts = PETSc.Options()
    for key, value in options.items():
        opts[f"{prefix}{key}"] = value
    try:
        yield
    finally:
        for key in options:
            del opts[f"{prefix}{key}"]


def check_converged(ksp: PETSc.KSP, what: str) -> int:
    reason = ksp.getConvergedReason()
    if reason < 0:
        raise SolverDivergedError(f"{what} solve diverged: KSP_{_REASONS.get(reason, reason)} after {ksp.getIterationNumber()} iterations")
    return ksp.getIterationNumber()


def rigid_body_modes(V) -> PETSc.NullSpace:
    """Near-nullspace of 2D elasticity (two translations, one rotation), orthonormalised."""
    index_map, bs = V.dofmap.index_map, V.dofmap.index_map_bs
    n_local = index_map.size_local
    basis = [la.create_petsc_vector(index_map, bs) for _ in range(3)]
    x = V.tabulate_dof_coordinates()[:n_local]
    with basis[0].localForm() as b0, basis[1].localForm() as b1, basis[2].localForm() as b2:
        b0.array[:] = 0.0
        b1.array[:] = 0.0
        b0.array[0 : bs * n_local : bs] = 1.0
        b1.array[1 : bs * n_local : bs] = 1.0
        b2.array[:] = 0.0
        b2.array[0 : bs * n_local : bs] = -x[:, 1]
        b2.array[1 : bs * n_local : bs] = x[:, 0]
    la.orthonormalize(basis)
    return PETSc.NullSpace().create(vectors=basis)


#: an update that changes more than this share of the cells assembles the whole matrix instead
#: (cheaper: the difference form evaluates two stiffnesses per cell)
FULL_ASSEMBLY_SHARE = 0.5


class IncrementalStiffness:
    """The equilibrium matrix kept up to date by assembling only what changed.

    A(g) = sum over Gauss points of g(phi_q) K_q is linear in the degradation at each Gauss
    point. ``assembled`` holds the phi (Gauss points) the matrix was last assembled with; an
    update assembles K(g(phi)) - K(g(phi_assembled)) over the cells where g moved, at one of
    their Gauss points, by more than ``tolerance`` times itself (0: any change) and adds it into
    the matrix, so the matrix is that of a degradation within a factor (1 +- tolerance) of the
    current one at every Gauss point (exact with tolerance 0, to round-off): the solution of
    the matrix used is within ~tolerance of the exact one in the energy norm. Relative, not
    absolute: in the crack g is near 0 and a small absolute change is a large one there.
    Rows and columns of Dirichlet dofs are left out of the difference (they keep the 1 on the
    diagonal of the full assembly).
    """

    def __init__(self, problem: FractureProblem, tolerance: float):
        self.problem, self.tolerance = problem, float(tolerance)
        self.assembled = fem.Function(problem.Q, name="phase_field_assembled")
        domain = problem.domain
        u, v = ufl.TrialFunction(problem.V), ufl.TestFunction(problem.V)
        model = problem.model
        difference = (model.equilibrium_form(u, v, problem.phase_field_gp, problem.material)
                      - model.equilibrium_form(u, v, self.assembled, problem.material))
        self._tdim = domain.topology.dim
        nothing = dmesh.meshtags(domain, self._tdim, np.empty(0, dtype=np.int32), np.empty(0, dtype=np.int32))
        self._form = difference * ufl.Measure("dx", domain=domain, metadata=QUADRATURE, subdomain_data=nothing)(1)
        # compiled once; each update only builds a dolfinx Form over the changed cells
        self._ufcx, module, _ = jit.ffcx_jit(domain.comm, self._form, form_compiler_params={"scalar_type": "double"})
        self._pointer = int(module.ffi.cast("uintptr_t", module.ffi.addressof(self._ufcx)))
        coefficients = self._form.coefficients()
        self._coefficients = [coefficients[self._ufcx.original_coefficient_position[i]]._cpp_object
                              for i in range(self._ufcx.num_coefficients)]
        self._spaces = [problem.V._cpp_object, problem.V._cpp_object]
        self._mesh = domain.ufl_domain().ufl_cargo()   # the C++ mesh, as dolfinx.fem.form passes it
        self.full_assemblies = 0
        self.changed_cells = 0   # of the last update

    def degradation(self, phase_field: np.ndarray) -> np.ndarray:
        return self.problem.model.degradation(phase_field, self.problem.material["residual_stiffness"])

    def assemble_full(self, A: PETSc.Mat) -> None:
        p = self.problem
        A.zeroEntries()
        fem_petsc.assemble_matrix(A, p.equilibrium_form, bcs=p.bcs)
        A.assemble()
        self.assembled.x.array[:] = p.phase_field_gp.x.array
        self.full_assemblies += 1
        self.changed_cells = p.n_cells_owned

    def assemble(self, A: PETSc.Mat) -> None:
        """The whole matrix the first time, the change of the cells whose degradation moved after."""
        if self.full_assemblies == 0:
            self.assemble_full(A)
        else:
            self.update(A)

    def update(self, A: PETSc.Mat) -> int:
        """Add the stiffness change of the cells whose degradation moved; returns their number."""
        p = self.problem
        q = p.q_dofs[: p.n_cells_owned]
        g_now, g_then = self.degradation(p.phase_field_gp.x.array[q]), self.degradation(self.assembled.x.array[q])
        moved = np.abs(g_now - g_then) > self.tolerance * np.maximum(g_now, g_then)
        cells = np.flatnonzero(moved.any(axis=1)).astype(np.int32)
        self.changed_cells = len(cells)
        changed, total = p.comm.allreduce(np.array([len(cells), p.n_cells_owned]), op=MPI.SUM)
        if changed == 0:
            return 0
        if changed > FULL_ASSEMBLY_SHARE * total:   # the difference form costs twice the full one per cell
            self.assemble_full(A)
            return self.changed_cells
        tags = dmesh.meshtags(p.domain, self._tdim, cells, np.ones(len(cells), dtype=np.int32))
        subdomains = {dcpp.fem.IntegralType.cell: tags, dcpp.fem.IntegralType.exterior_facet: None,
                      dcpp.fem.IntegralType.interior_facet: None, dcpp.fem.IntegralType.vertex: None}
        form = dcpp.fem.Form_float64(self._pointer, self._spaces, self._coefficients, [], subdomains, self._mesh)
        dcpp.fem.petsc.assemble_matrix(A, form, dcpp.fem.pack_constants(form), dcpp.fem.pack_coefficients(form), p.bcs)
        A.assemble()
        self.assembled.x.array[q[cells]] = p.phase_field_gp.x.array[q[cells]]
        return len(cells)

    def relative_change(self, reference: np.ndarray) -> float:
        """sum |g(phi_assembled) - g(reference)| / sum g(reference) over the owned Gauss points
        (``reference``: a phi array of the same layout): the share of the stiffness that moved."""
        p = self.problem
        owned = p.owned_q_dofs
        g_now, g_then = self.degradation(self.assembled.x.array[owned]), self.degradation(reference[owned])
        moved = p.comm.allreduce(float(np.abs(g_now - g_then).sum()), op=MPI.SUM)
        total = p.comm.allreduce(float(g_then.sum()), op=MPI.SUM)
        return moved / total if total > 0 else 0.0


class PreconditionerReuse:
    """When the displacement preconditioner is rebuilt (a preset's ``displacement_reuse``).

    The preconditioner (e.g. the GAMG hierarchy) built for one matrix is kept for the following
    solves, whose operator is always the current matrix (only the preconditioner is stale, so a
    converged solve is as accurate as with a fresh one). It is rebuilt before a solve when the
    previous solve took more than ``refresh_iterations`` Krylov iterations, or when the stiffness
    moved, since it was built, by more than ``refresh_stiffness_change`` (relative L1 change of
    g(phi) over the Gauss points, see IncrementalStiffness.relative_change); and a solve that did
    not converge with a kept preconditioner is redone once with a fresh one.
    """

    def __init__(self, settings: dict):
        self.max_iterations = int(settings["refresh_iterations"])
        self.max_change = float(settings["refresh_stiffness_change"])
        self.refreshes = 0
        self.reasons: list[str] = []          # why each refresh happened (first, iterations, stiffness, diverged)
        self._built_with: np.ndarray | None = None
        self._last_iterations = 0

    def needs_refresh(self, stiffness: IncrementalStiffness) -> str | None:
        if self._built_with is None:
            return "first"
        if self._last_iterations > self.max_iterations:
            return "iterations"
        if stiffness.relative_change(self._built_with) > self.max_change:
            return "stiffness"
        return None

    def refreshed(self, stiffness: IncrementalStiffness, reason: str) -> None:
        self.refreshes += 1
        self.reasons.append(reason)
        self._built_with = stiffness.assembled.x.array.copy()

    def solved(self, iterations: int) -> None:
        self._last_iterations = iterations


def solve_reusing(ksp: PETSc.KSP, policy: PreconditionerReuse, stiffness, b: PETSc.Vec, x: PETSc.Vec, options: dict,
                  refresh=None) -> int:
    """Solve with the kept preconditioner unless ``policy`` asks for a fresh one; a solve that
    fails with a kept one is redone once with a fresh one (from the same start). ``refresh``:
    called before a fresh preconditioner is built (to hand the KSP the matrix to factor).
    Returns the Krylov iterations."""
    pc = ksp.getPC()
    reason = policy.needs_refresh(stiffness)
    start = None if reason else x.copy()
    if reason:
        if refresh is not None:
            refresh()
        policy.refreshed(stiffness, reason)
    pc.setReusePreconditioner(reason is None)
    with petsc_options("displacement_", options if reason else {}):
        ksp.solve(b, x)
    if ksp.getConvergedReason() < 0 and start is not None:
        start.copy(x)
        if refresh is not None:
            refresh()
        pc.setReusePreconditioner(False)
        policy.refreshed(stiffness, "diverged")
        with petsc_options("displacement_", options):
            ksp.solve(b, x)
    iterations = check_converged(ksp, "displacement")
    policy.solved(iterations)
    return iterations


class FractureProblem:
    """Fields and the equilibrium/history parts of one scene.

    Attributes (dolfinx Functions): ``displacement`` (vector Q1), ``phase_field`` (nodal Q1,
    FEM's unknown), ``phase_field_gp`` (Gauss points; the phi used in g(phi)), ``history`` and
    ``history_previous`` (Gauss points, N/mm^2). ``pixels`` maps Gauss points to pixels.
    """

    def __init__(self, domain, scene: dict, material: dict, petsc: dict, comm=MPI.COMM_WORLD):
        self.domain, self.scene, self.material, self.comm = domain, scene, material, comm
        self.model = phase_field_model(material)   # ifenn.models: g(phi), the driving force, the forms
        cell = domain.ufl_cell()
        self.V = fem.VectorFunctionSpace(domain, ("Lagrange", 1))
        self.W = fem.FunctionSpace(domain, ("Lagrange", 1))
        self.Q = fem.FunctionSpace(domain, ufl.FiniteElement("Quadrature", cell, 2, quad_scheme="default"))
        self.dx = ufl.Measure("dx", domain=domain, metadata=QUADRATURE)

        self.displacement = fem.Function(self.V, name="displacement")
        self.phase_field = fem.Function(self.W, name="phase_field")
        self.phase_field_gp = fem.Function(self.Q, name="phase_field_gp")
        self.history = fem.Function(self.Q, name="history")
        self.history_previous = fem.Function(self.Q, name="history_previous")

        tdim = domain.topology.dim
        cell_map = domain.topology.index_map(tdim)
        self.n_cells_owned = cell_map.size_local
        self.local_cells = np.arange(cell_map.size_local + cell_map.num_ghosts, dtype=np.int32)
        self.quadrature_points, _ = basix.make_quadrature(basix.CellType.quadrilateral, 2)
        self.q_dofs = self.Q.dofmap.list.array.reshape(-1, len(self.quadrature_points))

        # Pixel grid = Gauss-point grid.
        gp_coordinates = fem.Expression(ufl.SpatialCoordinate(domain), self.quadrature_points).eval(self.local_cells)
        self.gauss_point_coordinates = gp_coordinates.reshape(len(self.local_cells), -1, 2)  # (cells, 4, 2), mm
        gp_coordinates = self.gauss_point_coordinates
        self.pixels = PixelGrid.for_scene(scene)
        self.pixel_of_q_dof = np.empty(self.Q.dofmap.index_map.size_local + self.Q.dofmap.index_map.num_ghosts, dtype=np.int64)
        self.pixel_of_q_dof[self.q_dofs] = self.pixels.pixel_index(gp_coordinates)
        self.owned_q_dofs = self.q_dofs[: self.n_cells_owned].ravel()
        # the pixels of the solid (a cut-out's pixels have no Gauss point: 0 in every image)
        self.solid = geometry.solid_pixels(scene, self.pixels) if scene.get("cutouts") else None
        if self.comm.size == 1:  # serial: the image is one gather (the map is one-to-one, checked here)
            index = self.pixel_of_q_dof[self.owned_q_dofs]
            self.pixels.image_from(index, np.zeros(len(index)), self.solid)
            self.q_dof_of_pixel = np.empty(self.pixels.nx_px * self.pixels.ny_px, dtype=np.int64)
            self.q_dof_of_pixel[index] = self.owned_q_dofs
            self._solid_pixel_index = None if self.solid is None else index

        self._build_boundary_conditions()
        self._build_equilibrium(petsc["displacement"], petsc.get("displacement_reuse"), petsc.get("displacement_matrix", "aij"))
        self._tensile_energy = fem.Expression(
            self.model.driving_force(self.displacement, material),
            self.quadrature_points,
        )
        self.set_initial_history()

    # ------------------------------------------------------------------ set-up
    def _build_boundary_conditions(self) -> None:
        """Dirichlet conditions of the scene's supports and loads (ifenn.fem.supports): edges and
        their parts through the boundary facets they cover, points through their vertex."""
        tdim = self.domain.topology.dim
        fdim = tdim - 1
        self.domain.topology.create_connectivity(0, tdim)
        self.load = fem.Constant(self.domain, PETSc.ScalarType(0.0))
        self.load_reversed = fem.Constant(self.domain, PETSc.ScalarType(0.0))   # "-load": pushed the other way
        zero = fem.Constant(self.domain, PETSc.ScalarType(0.0))
        self.bcs, held = [], []
        n_owned = self.V.dofmap.index_map.size_local * self.V.dofmap.index_map_bs
        for condition in supports.conditions(self.scene):
            def marker(x, condition=condition):
                return condition.selects(x[0], x[1])

            if condition.is_point:
                entities, dim = dmesh.locate_entities(self.domain, 0, marker), 0
            else:
                entities, dim = dmesh.locate_entities_boundary(self.domain, fdim, marker), fdim
            sub = self.V.sub(condition.component)
            dofs = fem.locate_dofs_topological(sub, dim, entities)
            value = {"load": self.load, "-load": self.load_reversed}.get(condition.kind, zero)
            self.bcs.append(fem.dirichletbc(value, dofs, sub))
            held.append((dofs, condition.kind))
        loaded, sign = supports.loaded_dofs(held)
        self._loaded_dofs_with_ghosts = loaded
        self.loaded_dofs = loaded[loaded < n_owned]
        #: +1 on dofs pulled by the load, -1 on those pushed the other way ("-load")
        self.load_sign = sign[loaded < n_owned]

    def _build_equilibrium(self, options: dict, reuse: dict | None = None, matrix_type: str = "aij") -> None:
        """Forms, matrix and KSP of the displacement solve. ``reuse`` (a preset's
        ``displacement_reuse``, None: rebuild everything every solve, the classic path): keep
        the preconditioner across solves (PreconditionerReuse), assemble only the cells whose
        degradation moved (IncrementalStiffness) and start from the previous solution scaled to
        the new load. ``matrix_type`` (a preset's ``displacement_matrix``): PETSc's storage of
        the matrix, aij or baij (2x2 blocks: what ifenn.fem.factor factors fast)."""
        u, v = ufl.TrialFunction(self.V), ufl.TestFunction(self.V)
        self.equilibrium_form = fem.form(self.model.equilibrium_form(u, v, self.phase_field_gp, self.material) * self.dx)
        # the reaction on the loaded dofs comes only from the cells that hold them (owned or
        # ghost dofs: the ghosts' contributions reach their owner in reaction_force)
        index_map = self.V.dofmap.index_map
        cell_blocks = self.V.dofmap.list.array.reshape(self.local_cells.size, -1)[: self.n_cells_owned]
        loaded_blocks = np.zeros(index_map.size_local + index_map.num_ghosts, dtype=bool)
        loaded_blocks[self._loaded_dofs_with_ghosts // self.V.dofmap.index_map_bs] = True
        loaded_cells = np.flatnonzero(loaded_blocks[cell_blocks].any(axis=1)).astype(np.int32)
        edge = dmesh.meshtags(self.domain, self.domain.topology.dim, loaded_cells, np.ones(len(loaded_cells), dtype=np.int32))
        dx_loaded = ufl.Measure("dx", domain=self.domain, metadata=QUADRATURE, subdomain_data=edge)(1)
        self.internal_force_form = fem.form(self.model.equilibrium_form(self.displacement, v, self.phase_field_gp, self.material) * dx_loaded)
        # BAIJ in serial only: in parallel the factor is MUMPS's, whose Cholesky takes no BAIJ
        serial_baij = matrix_type == "baij" and self.comm.size == 1
        self.A_u = fem_petsc.create_matrix(self.equilibrium_form, "baij" if serial_baij else None)
        self.A_u.setNearNullSpace(rigid_body_modes(self.V))
        self.b_u = fem_petsc.create_vector(self.internal_force_form)
        self.internal_force = fem_petsc.create_vector(self.internal_force_form)
        self.ksp_u = PETSc.KSP().create(self.comm)
        self.ksp_u.setOperators(self.A_u)
        configure_ksp(self.ksp_u, "displacement_", options)
        if self.ksp_u.getType() != PETSc.KSP.Type.PREONLY:
            self.ksp_u.setInitialGuessNonzero(True)
        self.stiffness = self.reuse = None
        self._displacement_options = dict(options)
        self.scaled_initial_guess = False
        if reuse is not None:
            self.stiffness = IncrementalStiffness(self, reuse["assembly_tolerance"])
            self.reuse = PreconditionerReuse(reuse)
            self.scaled_initial_guess = reuse["initial_guess"] == "scaled"
        self._solved_load: float | None = None   # the load of the solution held in displacement
        self.displacement_iterations = 0

    def set_initial_history(self) -> None:
        """H0 of 'history' notches at the Gauss points (the model's ``notch_history``, Borden et al. 2012)."""
        notches = [n for n in self.scene.get("notches", []) if n["kind"] == "history"]
        values = np.zeros(len(self.pixel_of_q_dof))
        if notches:
            coords = self.gauss_point_coordinates.reshape(-1, 2)
            distance = np.min([distance_to_segment(coords, n["start"], n["end"]) for n in notches], axis=0)
            values[self.q_dofs.ravel()] = self.model.notch_history(distance, self.material)
        self.history.x.array[:] = values
        self.history_previous.x.array[:] = values

    # ------------------------------------------------------------------ steps
    def solve_displacement(self, load_value: float) -> int:
        """Assemble and solve equilibrium with the current phase_field_gp; returns iterations."""
        self.load.value = load_value
        self.load_reversed.value = -load_value
        if self.reuse is None:
            self.A_u.zeroEntries()
            fem_petsc.assemble_matrix(self.A_u, self.equilibrium_form, bcs=self.bcs)
            self.A_u.assemble()
        else:
            self.stiffness.assemble(self.A_u)
        with self.b_u.localForm() as local:
            local.set(0.0)
        fem_petsc.apply_lifting(self.b_u, [self.equilibrium_form], bcs=[self.bcs])
        self.b_u.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        fem_petsc.set_bc(self.b_u, self.bcs)
        if self.scaled_initial_guess and self._solved_load and load_value != self._solved_load:
            # exact for an unchanged stiffness: the solution is linear in the prescribed displacement
            self.displacement.vector.scale(load_value / self._solved_load)
        if self.reuse is None:
            iterations = self._solve_u()
        else:
            iterations = self._solve_u_reusing()
        self._solved_load = load_value
        self.displacement_iterations = iterations
        return iterations

    def _solve_u(self) -> int:
        self.ksp_u.solve(self.b_u, self.displacement.vector)
        self.displacement.x.scatter_forward()
        return check_converged(self.ksp_u, "displacement")

    def _solve_u_reusing(self) -> int:
        iterations = solve_reusing(self.ksp_u, self.reuse, self.stiffness, self.b_u, self.displacement.vector,
                                   self._displacement_options)
        self.displacement.x.scatter_forward()
        return iterations

    def update_history(self) -> None:
        """H = max(H_previous_increment, psi_0^+(u)) at every Gauss point (local + ghost cells)."""
        psi = self._tensile_energy.eval(self.local_cells)
        values = np.empty_like(self.history.x.array)
        values[self.q_dofs] = psi
        np.maximum(self.history_previous.x.array, values, out=self.history.x.array)

    def accept_increment(self) -> None:
        self.history_previous.x.array[:] = self.history.x.array

    def snapshot(self) -> dict:
        """Copies of the fields an attempted increment changes (u, nodal and Gauss-point phi);
        H is restored from the accepted increment's own (``history_previous``)."""
        return {"displacement": self.displacement.x.array.copy(), "phase_field": self.phase_field.x.array.copy(),
                "phase_field_gp": self.phase_field_gp.x.array.copy()}

    def restore(self, snapshot: dict) -> None:
        """Undo an attempted increment: the fields of ``snapshot`` and the accepted history."""
        for name in ("displacement", "phase_field", "phase_field_gp"):
            getattr(self, name).x.array[:] = snapshot[name]
        self.history.x.array[:] = self.history_previous.x.array

    def reaction_force(self) -> float:
        """Sum of the internal force on the loaded dofs times the scene's thickness (``material
        ["thickness"]``, mm; absent: N per mm of thickness)."""
        with self.internal_force.localForm() as local:
            local.set(0.0)
        fem_petsc.assemble_vector(self.internal_force, self.internal_force_form)
        self.internal_force.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        local = float(self.internal_force.array_r[self.loaded_dofs] @ self.load_sign)
        return self.material.get("thickness", 1.0) * self.comm.allreduce(local, op=MPI.SUM)

    def max_owned(self, function) -> float:
        n = function.function_space.dofmap.index_map.size_local * function.function_space.dofmap.index_map_bs
        return self.comm.allreduce(float(function.x.array[:n].max(initial=-np.inf)), op=MPI.MAX)

    # ------------------------------------------------------------------ pixels
    def pixels_from_gauss_points(self, function) -> np.ndarray | None:
        """Gauss-point field -> (ny_px, nx_px) pixel image on rank 0 (None elsewhere)."""
        if self.comm.size == 1 and self.solid is None:   # take(mode="clip"): the indices are valid, and it skips their check
            return np.take(function.x.array, self.q_dof_of_pixel, mode="clip").reshape(self.pixels.shape)
        if self.comm.size == 1:
            image = np.zeros(self.pixels.nx_px * self.pixels.ny_px)
            image[self._solid_pixel_index] = function.x.array[self.owned_q_dofs]
            return image.reshape(self.pixels.shape)
        index = self.pixel_of_q_dof[self.owned_q_dofs]
        values = function.x.array[self.owned_q_dofs]
        if self.comm.size > 1:
            gathered = self.comm.gather((index, values), root=0)
            if self.comm.rank != 0:
                return None
            index = np.concatenate([g[0] for g in gathered])
            values = np.concatenate([g[1] for g in gathered])
        return self.pixels.image_from(index, values, self.solid)

    def gauss_points_from_pixels(self, image: np.ndarray | None, function) -> None:
        """Pixel image (given on rank 0) -> Gauss-point field on every rank (incl. ghosts)."""
        if self.comm.size > 1:
            image = self.comm.bcast(image, root=0)
        np.take(np.ravel(image), self.pixel_of_q_dof, out=function.x.array, mode="clip")


def distance_to_segment(points: np.ndarray, start, end) -> np.ndarray:
    """Distance (mm) of each of ``points`` (n, 2) to the segment from ``start`` to ``end``."""
    a, b = np.asarray(start, float), np.asarray(end, float)
    ab = b - a
    t = np.clip(((points - a) @ ab) / (ab @ ab), 0.0, 1.0)
    return np.linalg.norm(points - (a + t[:, None] * ab), axis=1)
