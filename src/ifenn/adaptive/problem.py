"""The displacement on a graded quadtree mesh, the phase field and the history on the pixel grid.

The state of a run is two pixel images: the history H and the phase field phi (on the uniform
grid of :class:`ifenn.pixels.PixelGrid`). The displacement mesh (a :class:`Quadtree`, fine cells
of ``pixels_per_fine_cell`` x that many pixels) is disposable: this class is built for one mesh
and only reads and writes the images.

- Equilibrium: Q1 displacements on the leaves, assembled by dolfinx over every cell with g(phi)
  at 2 x 2 Gauss points, then reduced to the free nodes by the hanging-node constraints: K_r =
  P^T K P, with P the (dofs x free dofs) matrix that sets a hanging node to the mean of its
  edge's ends (a conforming Q1 space on a non-conforming cell complex). Dirichlet rows and
  columns of K_r are zeroed (PETSc's MatZeroRowsColumns, which moves the prescribed values to
  the right-hand side); the solve is the run's displacement KSP (its preset's options).
- phi at a Gauss point: the pixel it lies in when a cell is one pixel wide, else the mean of the
  pixels of the cell's quadrant that holds it (2 x 2 pixels per fine cell: the pixel itself, as
  the uniform mesh's Gauss point = pixel map). Never across a slit: leaves do not straddle one.
- H at a pixel: psi_0^+ of the displacement at the pixel's centre, in the leaf that holds it,
  and the max with the pixel's H of the last increment; so irreversibility is a property of the
  image and survives any remesh.
- Reaction force: P^T (K u) summed over the loaded free dofs (a hanging node on a loaded edge
  hands its force to its ends, which are on the same edge).

Serial only (one process owns the whole mesh and the images).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse
import ufl
from dolfinx import fem
from dolfinx import mesh as dmesh
from dolfinx.fem import petsc as fem_petsc
from mpi4py import MPI
from petsc4py import PETSc

from ifenn import geometry
from ifenn.adaptive.quadtree import Quadtree
from ifenn.fem import supports
from ifenn.fem.factor import as_blocks
from ifenn.fem.problem import (
    QUADRATURE,
    IncrementalStiffness,
    PreconditionerReuse,
    check_converged,
    configure_ksp,
    petsc_options,
    solve_reusing,
)
from ifenn.models import phase_field_model
from ifenn.pixels import PixelGrid


def dolfinx_mesh(tree: Quadtree):
    """The quadtree's leaves as a dolfinx quadrilateral mesh on this process alone."""
    element = ufl.VectorElement("Lagrange", ufl.quadrilateral, 1)
    return dmesh.create_mesh(MPI.COMM_SELF, tree.cells, tree.points, ufl.Mesh(element))


class AdaptiveMeshProblem:
    """Equilibrium on one quadtree mesh, with phi and H on the pixel grid (module doc).

    ``pixels``: the scene's pixel grid; its spacing times ``pixels_per_fine_cell`` is the
    quadtree's finest cell. ``reuse`` (a preset's ``displacement_reuse``) and ``matrix_type`` (its
    ``displacement_matrix``): as on the uniform mesh (:class:`ifenn.fem.problem.FractureProblem`),
    the preconditioner is kept across the solves on this mesh, only the cells whose degradation
    moved are reassembled and a solve starts from the last solution scaled to the new load; with
    ``baij``, the reduced matrix is factored as 2 x 2 blocks (:func:`ifenn.fem.factor.as_blocks`).
    """

    def __init__(self, tree: Quadtree, scene: dict, material: dict, displacement_options: dict, pixels: PixelGrid,
                 reuse: dict | None = None, matrix_type: str = "aij"):
        self.tree, self.scene, self.material, self.pixels = tree, scene, material, pixels
        self.model = phase_field_model(material)   # ifenn.models: g(phi), the driving force, the forms
        ratio = tree.h_fine / pixels.h_px
        self.pixels_per_fine_cell = int(round(ratio))
        if abs(ratio - self.pixels_per_fine_cell) > 1e-9 or self.pixels_per_fine_cell < 1:
            raise ValueError(f"the finest cell ({tree.h_fine:g} mm) must be a whole number of pixels ({pixels.h_px:g} mm)")
        self.domain = domain = dolfinx_mesh(tree)
        self.comm = domain.comm
        self.V = fem.VectorFunctionSpace(domain, ("Lagrange", 1))
        self.Q = fem.FunctionSpace(domain, ufl.FiniteElement("Quadrature", domain.ufl_cell(), 2, quad_scheme="default"))
        self.dx = ufl.Measure("dx", domain=domain, metadata=QUADRATURE)
        self.displacement = fem.Function(self.V, name="displacement")
        self.phase_field_gp = fem.Function(self.Q, name="phase_field_gp")
        n_cells = domain.topology.index_map(2).size_local
        self.cells = np.arange(n_cells, dtype=np.int32)
        self.quadrature_points = self._quadrature_points()
        self.q_dofs = self.Q.dofmap.list.array.reshape(n_cells, -1)

        # cells: lower-left corner and size from the geometry (dolfinx may reorder cells)
        geometry = domain.geometry.x[domain.geometry.dofmap.array.reshape(n_cells, -1), :2]
        self.cell_low = geometry.min(axis=1)
        self.cell_size_px = np.rint((geometry.max(axis=1) - self.cell_low)[:, 0] / pixels.h_px).astype(np.int64)
        self._build_pixel_maps()
        self._build_constraints()
        self._build_boundary_conditions()
        u, v = ufl.TrialFunction(self.V), ufl.TestFunction(self.V)
        self.stiffness_form = self.equilibrium_form = fem.form(self.model.equilibrium_form(u, v, self.phase_field_gp, material) * self.dx)
        self.K = fem_petsc.create_matrix(self.stiffness_form)
        # what IncrementalStiffness reads of a problem: one process owns every cell, no bcs in K
        self.n_cells_owned, self.owned_q_dofs, self.bcs = n_cells, self.q_dofs.ravel(), []
        # the internal force on the loaded dofs comes from the cells that hold them
        loaded_blocks = np.zeros(self.V.dofmap.index_map.size_local, dtype=bool)
        loaded_blocks[self.block_of_node[np.concatenate([self.free_nodes[self.loaded_dofs // 2],
                                                         tree.hanging[np.isin(tree.masters, self.free_nodes[self.loaded_dofs // 2]).any(axis=1)]])]] = True
        cells = np.flatnonzero(loaded_blocks[self.V.dofmap.list.array.reshape(n_cells, -1)].any(axis=1)).astype(np.int32)
        tags = dmesh.meshtags(domain, 2, cells, np.ones(len(cells), dtype=np.int32))
        dx_loaded = ufl.Measure("dx", domain=domain, metadata=QUADRATURE, subdomain_data=tags)(1)
        self.internal_force_form = fem.form(self.model.equilibrium_form(self.displacement, v, self.phase_field_gp, material) * dx_loaded)
        self.internal_force = fem_petsc.create_vector(self.internal_force_form)
        self.K_reduced = None
        self.ksp = PETSc.KSP().create(self.comm)
        configure_ksp(self.ksp, "displacement_", displacement_options)
        self._displacement_options = dict(displacement_options)
        self.stiffness = self.reuse = None
        self.scaled_initial_guess = False
        self._blocks = matrix_type == "baij"
        self._factored: PETSc.Mat | None = None   # the blocked copy a kept factor was built from
        self.solved_load: float | None = None     # the load of the solution held in u_reduced
        if reuse is not None:
            self.stiffness = IncrementalStiffness(self, reuse["assembly_tolerance"])
            self.reuse = PreconditionerReuse(reuse)
            self.scaled_initial_guess = reuse["initial_guess"] == "scaled"
        self._nullspace = self._near_nullspace()
        self.u_reduced = PETSc.Vec().createSeq(self.n_free_dofs)
        self.rhs = PETSc.Vec().createSeq(self.n_free_dofs)
        self._tensile = self.model.driving_force(self.displacement, material)
        self._psi_expressions = {m: fem.Expression(self._tensile, points) for m, (points, _, _) in self._pixel_centres.items()}
        self._u_expressions = {m: fem.Expression(self.displacement, points) for m, (points, _, _) in self._pixel_centres.items()}

    def _quadrature_points(self) -> np.ndarray:
        import basix

        points, _ = basix.make_quadrature(basix.CellType.quadrilateral, 2)
        return points

    # ------------------------------------------------------------------ maps
    def _build_pixel_maps(self) -> None:
        """The sampling matrix pixels -> Gauss points of phi, and per cell width m (pixels) the
        reference points of the pixel centres in a cell and their pixel indices."""
        grid, n_px = self.pixels, self.pixels.nx_px * self.pixels.ny_px
        low_px = np.rint((self.cell_low - [grid.x0, grid.y0]) / grid.h_px).astype(np.int64)   # (cells, 2): ix, iy
        gauss = fem.Expression(ufl.SpatialCoordinate(self.domain), self.quadrature_points).eval(self.cells).reshape(len(self.cells), -1, 2)
        rows, cols, weights = [], [], []
        n_gp = gauss.shape[1]
        self._pixel_centres = {}
        for m in np.unique(self.cell_size_px):
            cells = np.flatnonzero(self.cell_size_px == m).astype(np.int32)
            q = self.q_dofs[cells]                                             # (n, gp)
            if m == 1:
                rows.append(q.ravel())
                cols.append(np.repeat(low_px[cells, 1] * grid.nx_px + low_px[cells, 0], n_gp))
                weights.append(np.ones(q.size))
            else:
                half = m // 2
                centre = (low_px[cells] + 0.5 * m) * grid.h_px + [grid.x0, grid.y0]
                quadrant = (gauss[cells] > centre[:, None, :]).astype(np.int64)   # (n, gp, 2)
                corner = low_px[cells, None, :] + half * quadrant                  # (n, gp, 2)
                dy, dx = np.meshgrid(np.arange(half), np.arange(half), indexing="ij")
                iy = corner[..., 1, None] + dy.ravel()
                ix = corner[..., 0, None] + dx.ravel()
                rows.append(np.repeat(q.ravel(), half * half))
                cols.append((iy * grid.nx_px + ix).ravel())
                weights.append(np.full(q.size * half * half, 1.0 / (half * half)))
            j, i = np.meshgrid(np.arange(m), np.arange(m), indexing="ij")
            points = np.column_stack([(i.ravel() + 0.5) / m, (j.ravel() + 0.5) / m])
            where = fem.Expression(ufl.SpatialCoordinate(self.domain), points).eval(cells).reshape(len(cells), -1, 2)
            self._pixel_centres[int(m)] = (points, cells.astype(np.int32), grid.pixel_index(where).ravel())
        n_q = self.Q.dofmap.index_map.size_local
        self.sample = scipy.sparse.csr_matrix((np.concatenate(weights), (np.concatenate(rows), np.concatenate(cols))), shape=(n_q, n_px))
        covered = np.bincount(np.concatenate([index for *_, index in self._pixel_centres.values()]), minlength=n_px)
        solid = np.ravel(geometry.solid_pixels(self.scene, grid)) if self.scene.get("cutouts") else np.ones(n_px, dtype=bool)
        if covered.size != n_px or (covered[solid] != 1).any() or covered[~solid].any():
            raise ValueError(f"the mesh's cells do not cover the solid of the {grid.shape} pixel grid one pixel centre each")

    def _build_constraints(self) -> None:
        """P: dofs -> free dofs (hanging nodes the mean of their edge's ends), as a PETSc matrix."""
        tree = self.tree
        n_cells, bs = len(self.cells), 2
        blocks = self.V.dofmap.list.array.reshape(n_cells, -1)
        node_index = np.asarray(self.domain.geometry.input_global_indices, dtype=np.int64)[
            self.domain.geometry.dofmap.array.reshape(n_cells, -1)]
        n_blocks = self.V.dofmap.index_map.size_local
        node_of_block = np.empty(n_blocks, dtype=np.int64)
        node_of_block[blocks] = node_index
        block_of_node = np.empty(tree.n_nodes, dtype=np.int64)
        block_of_node[node_of_block] = np.arange(n_blocks)
        free_nodes = tree.free_nodes()
        column_of_node = np.full(tree.n_nodes, -1, dtype=np.int64)
        column_of_node[free_nodes] = np.arange(len(free_nodes))
        self.node_of_block, self.block_of_node, self.free_nodes = node_of_block, block_of_node, free_nodes
        rows = [block_of_node[free_nodes], np.repeat(block_of_node[tree.hanging], 2)]
        cols = [column_of_node[free_nodes], column_of_node[tree.masters].ravel()]
        values = [np.ones(len(free_nodes)), np.full(2 * len(tree.hanging), 0.5)]
        r, c, w = np.concatenate(rows), np.concatenate(cols), np.concatenate(values)
        # two components per node
        r2 = np.concatenate([bs * r, bs * r + 1])
        c2 = np.concatenate([bs * c, bs * c + 1])
        w2 = np.concatenate([w, w])
        self.P_scipy = scipy.sparse.csr_matrix((w2, (r2, c2)), shape=(bs * n_blocks, bs * len(free_nodes)))
        self.P = PETSc.Mat().createAIJ(self.P_scipy.shape, csr=(self.P_scipy.indptr.astype(PETSc.IntType),
                                                                self.P_scipy.indices.astype(PETSc.IntType), self.P_scipy.data),
                                       comm=MPI.COMM_SELF)
        self.P.assemble()
        self.n_free_dofs = bs * len(free_nodes)
        self.free_coordinates = tree.points[free_nodes]

    def _build_boundary_conditions(self) -> None:
        """Prescribed free dofs (fixed: 0, load: the load), by the scene's supports and loads
        (ifenn.fem.supports), selected among the free nodes by their coordinates: the run makes the
        ends of parts and the points nodes of the mesh (supports.anchor_cells)."""
        x = self.free_coordinates
        held = [(2 * np.flatnonzero(c.selects(x[:, 0], x[:, 1])) + c.component, c.kind) for c in supports.conditions(self.scene)]
        self.loaded_dofs, self.load_sign = supports.loaded_dofs(held)   # sign: +1 pulled, -1 pushed ("-load")
        fixed = [dofs for dofs, kind in held if kind not in supports.LOADS]
        fixed = np.unique(np.concatenate(fixed)) if fixed else np.empty(0, dtype=np.int64)
        self.fixed_dofs = np.setdiff1d(fixed, self.loaded_dofs)
        self.prescribed = np.concatenate([self.fixed_dofs, self.loaded_dofs]).astype(PETSc.IntType)

    def _near_nullspace(self) -> PETSc.NullSpace:
        """Rigid-body modes on the free dofs, orthonormalised."""
        x = self.free_coordinates
        modes = np.zeros((3, self.n_free_dofs))
        modes[0, 0::2] = 1.0
        modes[1, 1::2] = 1.0
        modes[2, 0::2], modes[2, 1::2] = -x[:, 1], x[:, 0]
        q, _ = np.linalg.qr(modes.T)
        vectors = [PETSc.Vec().createWithArray(np.ascontiguousarray(q[:, i]), comm=MPI.COMM_SELF) for i in range(3)]
        return PETSc.NullSpace().create(vectors=vectors)

    # ------------------------------------------------------------------ fields
    def set_phase_field(self, phi: np.ndarray) -> None:
        """phi at the Gauss points from the pixel image (module doc)."""
        self.phase_field_gp.x.array[:] = self.sample @ np.ravel(phi)

    def tensile_energy(self) -> np.ndarray:
        """psi_0^+ of the current displacement at every pixel centre, as an image."""
        out = np.zeros(self.pixels.nx_px * self.pixels.ny_px)   # 0 in a cut-out
        for m, (_, cells, index) in self._pixel_centres.items():
            out[index] = self._psi_expressions[m].eval(cells).ravel()
        return out.reshape(self.pixels.shape)

    def displacement_at_pixels(self) -> np.ndarray:
        """u at every pixel centre, (ny_px, nx_px, 2) mm (a mesh-independent record)."""
        out = np.zeros((self.pixels.nx_px * self.pixels.ny_px, 2))   # 0 in a cut-out
        for m, (_, cells, index) in self._pixel_centres.items():
            out[index] = self._u_expressions[m].eval(cells).reshape(-1, 2)
        return out.reshape(*self.pixels.shape, 2)

    # ------------------------------------------------------------------ solve
    def solve_displacement(self, load: float) -> int:
        """Equilibrium with the current phi at the Gauss points and the load on the loaded dofs;
        returns the Krylov iterations."""
        if self.stiffness is None:
            self.K.zeroEntries()
            fem_petsc.assemble_matrix(self.K, self.stiffness_form)
            self.K.assemble()
        else:
            self.stiffness.assemble(self.K)
        self.K_reduced = self.K.PtAP(self.P, result=self.K_reduced)
        self.K_reduced.setNearNullSpace(self._nullspace)
        prescribed = self.u_reduced.duplicate()
        prescribed.set(0.0)
        prescribed.setValues(self.loaded_dofs.astype(PETSc.IntType), load * self.load_sign)
        prescribed.assemble()
        self.rhs.set(0.0)
        self.K_reduced.zeroRowsColumns(self.prescribed, 1.0, prescribed, self.rhs)
        if self.scaled_initial_guess and self.solved_load and load != self.solved_load:
            # exact for an unchanged stiffness: the solution is linear in the prescribed displacement
            self.u_reduced.scale(load / self.solved_load)
        self.u_reduced.setValues(self.prescribed, prescribed.getValues(self.prescribed))   # start on the prescribed values
        self.u_reduced.assemble()
        if self.ksp.getType() != PETSc.KSP.Type.PREONLY:
            self.ksp.setInitialGuessNonzero(True)
        if self.reuse is None:
            self.ksp.setOperators(self.K_reduced)
            with petsc_options("displacement_", self._displacement_options):
                self.ksp.solve(self.rhs, self.u_reduced)
            iterations = check_converged(self.ksp, "displacement")
        else:
            if self._factored is None:
                self.ksp.setOperators(self.K_reduced)   # the kept factor's matrix comes at its refresh
            iterations = solve_reusing(self.ksp, self.reuse, self.stiffness, self.rhs, self.u_reduced,
                                       self._displacement_options, refresh=self._refresh_factor)
        self.solved_load = load
        self.P.mult(self.u_reduced, self.displacement.vector)
        self.displacement.x.scatter_forward()
        return iterations

    def _refresh_factor(self) -> None:
        """Hand the preconditioner the current reduced matrix (as 2 x 2 blocks with ``baij``): the
        Krylov operator stays the reduced matrix itself, updated at every solve."""
        if not self._blocks:
            self._factored = self.K_reduced
        else:
            if self._factored is not None:
                self._factored.destroy()
            self._factored = as_blocks(self.K_reduced, 2)
        self.ksp.setOperators(self.K_reduced, self._factored)

    def reaction_force(self) -> float:
        """Sum of the internal force P^T f(u) over the loaded free dofs (N per mm of thickness),
        f assembled over the cells that hold a loaded dof (or a hanging node tied to them)."""
        with self.internal_force.localForm() as local:
            local.set(0.0)
        fem_petsc.assemble_vector(self.internal_force, self.internal_force_form)
        thickness = self.material.get("thickness", 1.0)   # mm; absent: N per mm of thickness
        return thickness * float((self.P_scipy.T @ self.internal_force.array)[self.loaded_dofs] @ self.load_sign)

    def internal_force_full(self) -> np.ndarray:
        """The internal force f(u) = int g(phi) sigma(u) : eps(v) of every cell, at every node of the
        mesh (hanging ones included; P^T f gives it on the free dofs), N per mm of thickness."""
        if not hasattr(self, "_internal_force_full_form"):
            v = ufl.TestFunction(self.V)
            self._internal_force_full_form = fem.form(
                self.model.equilibrium_form(self.displacement, v, self.phase_field_gp, self.material) * self.dx)
        return fem_petsc.assemble_vector(self._internal_force_full_form).array.copy()

    @property
    def n_dofs(self) -> int:
        """Displacement unknowns (free dofs)."""
        return self.n_free_dofs


def transfer_displacement(old: AdaptiveMeshProblem, new: AdaptiveMeshProblem) -> None:
    """Start ``new``'s displacement solve from ``old``'s solution: Q1 interpolation of the old
    field at the new free nodes (every node lies on the same fine lattice). A node on a slit takes
    its own face's value (twins from the cells above or right of the slit, the others from below
    or left). Only the initial guess of the Krylov solve: the solution is the new mesh's own."""
    t_old, t_new = old.tree, new.tree
    u_node = np.zeros((t_old.n_nodes, 2))
    u_node[old.node_of_block] = old.displacement.x.array.reshape(-1, 2)
    cell_of = np.full((t_old.ny, t_old.nx), -1, dtype=np.int64)   # -1: a cut-out's fine cell
    for size in np.unique(t_old.cell_size):
        cells = np.flatnonzero(t_old.cell_size == size)
        d = np.arange(size)
        rows = t_old.cell_origin[cells, 1, None, None] + d[None, :, None]
        cols = t_old.cell_origin[cells, 0, None, None] + d[None, None, :]
        cell_of[rows, cols] = cells[:, None, None]
    nodes = new.free_nodes
    grid_node = nodes.copy()   # a twin stands on its grid node's place
    twins = nodes >= t_new.n_grid_nodes
    grid_node[twins] = t_new.twin_of[nodes[twins] - t_new.n_grid_nodes]
    ij = t_new.node_ij[grid_node]
    cx, cy = np.minimum(ij[:, 0], t_old.nx - 1), np.minimum(ij[:, 1], t_old.ny - 1)
    twin = nodes >= t_new.n_grid_nodes
    for slit in t_new.slits:   # the other face's nodes look into the cell below / left of the slit
        along, across = (ij[:, 0], ij[:, 1]) if slit.axis == 0 else (ij[:, 1], ij[:, 0])
        on = (across == slit.line) & (along >= slit.start) & (along <= slit.stop) & ~twin & (across > 0)
        if slit.axis == 0:
            cy = np.where(on, ij[:, 1] - 1, cy)
        else:
            cx = np.where(on, ij[:, 0] - 1, cx)
    cell = cell_of[cy, cx]
    for dx, dy in ((-1, 0), (0, -1), (-1, -1)):   # a node on a cut-out's edge: a solid cell that has it
        missing = cell < 0
        if not missing.any():
            break
        cell[missing] = cell_of[np.maximum(cy[missing] + dy, 0), np.maximum(cx[missing] + dx, 0)]
    xi = (ij[:, 0] - t_old.cell_origin[cell, 0]) / t_old.cell_size[cell]
    eta = (ij[:, 1] - t_old.cell_origin[cell, 1]) / t_old.cell_size[cell]
    weights = np.column_stack([(1 - xi) * (1 - eta), xi * (1 - eta), (1 - xi) * eta, xi * eta])
    values = np.einsum("nk,nkc->nc", weights, u_node[t_old.cells[cell]])
    new.u_reduced.setArray(values.ravel())
    new.solved_load = old.solved_load
