"""Cut-outs: the domain minus rectangles. The mesh keeps the solid cells (a patch test stays
exact), every pixel operator cuts the links that leave the solid (no flux into a cut-out, the
removed pixels hold phi = 0), the certificate still bounds the error, and the config refuses a
cut-out off the mesh lines."""

from __future__ import annotations

import copy

import numpy as np
import pytest
import scipy.sparse
import scipy.sparse.linalg
from conftest import assert_certificate_bounds_the_error, assert_uniaxial_plane_strain

from ifenn import geometry
from ifenn.fem.mesh import build_mesh
from ifenn.pixel_equation.numpy_backend import PixelEquation, laplacian_matrix, solve_pixel_equation
from ifenn.pixels import PixelGrid, SlitCuts

GC, LC = 2.7, 0.15
# an L-shaped panel: the unit square without its upper right quadrant
L_PANEL = {"domain": {"x": [0.0, 1.0], "y": [0.0, 1.0]}, "elements": [20, 20],
           "cutouts": [{"x": [0.5, 1.0], "y": [0.5, 1.0]}],
           "boundary": {"bottom": {"x": "fixed", "y": "fixed"}, "points": [{"at": [0.95, 0.5], "y": "load"}]}}
MATERIAL = {"lame_lambda": 121154.0, "lame_mu": 80770.0, "Gc": GC, "lc": LC, "residual_stiffness": 0.0,
            "history_notch_B": 1e3}


def test_the_mesh_keeps_the_solid_cells_and_their_nodes():
    mesh = build_mesh(L_PANEL)
    assert len(mesh.cells) == 400 - 100
    assert len(mesh.points) == 21 * 21 - 10 * 10 and mesh.n_grid_nodes == len(mesh.points)
    centres = mesh.points[mesh.cells].mean(axis=1)
    assert not geometry.in_cutout(L_PANEL, centres[:, 0], centres[:, 1]).any()
    assert np.isin(np.arange(len(mesh.points)), mesh.cells).all()          # no node without a cell
    # the re-entrant corner and the cut-out's edges are nodes; the quadrant's inside is not
    assert (np.abs(mesh.points - [0.5, 0.5]).sum(axis=1) < 1e-12).sum() == 1
    assert not geometry.in_cutout(L_PANEL, mesh.points[:, 0], mesh.points[:, 1]).any()


def test_patch_test_on_a_mesh_with_a_cut_out(quick_config, tmp_path):
    """Uniaxial plane strain on a square whose right strip is cut out: the solid is a rectangle
    whose new right edge is free, so the field is linear and Q1 reproduces it to round-off, with
    the analytic force on the remaining top edge."""
    from conftest import build_problem

    scene = {"domain": {"x": [0.0, 1.0], "y": [0.0, 1.0]}, "elements": [8, 8],
             "cutouts": [{"x": [0.75, 1.0], "y": [0.0, 1.0]}],
             "boundary": {"bottom": {"y": "fixed"}, "left": {"x": "fixed"}, "top": {"y": "load"}}}
    problem, _ = build_problem(scene, MATERIAL, quick_config["solver"]["linear_solver_presets"]["direct"], tmp_path)
    problem.solve_displacement(1e-3)
    assert problem.V.tabulate_dof_coordinates()[:, 0].max() == pytest.approx(0.75)
    assert_uniaxial_plane_strain(problem, 1e-3, 0.75)
    # the pixel images of the problem: the removed pixels are 0, the solid ones the Gauss points'
    problem.update_history()
    image = problem.pixels_from_gauss_points(problem.history)
    solid = geometry.solid_pixels(scene, problem.pixels)
    assert (image[~solid] == 0).all() and (image[solid] > 0).all()


def test_patch_test_on_an_l_shaped_mesh_with_every_boundary_node_held(quick_config, tmp_path):
    """Any linear displacement prescribed on every boundary node of the L-shaped mesh (the
    cut-out's edges and the re-entrant corner included) is reproduced at every inner node."""
    from conftest import build_problem
    from dolfinx import fem
    from dolfinx import mesh as dmesh

    problem, _ = build_problem(L_PANEL, MATERIAL, quick_config["solver"]["linear_solver_presets"]["direct"], tmp_path)
    linear = fem.Function(problem.V)
    linear.interpolate(lambda x: np.vstack([1e-3 * (0.3 * x[0] - 0.2 * x[1]), 1e-3 * (0.1 * x[0] + 0.5 * x[1])]))
    domain = problem.domain
    domain.topology.create_connectivity(1, 2)
    facets = dmesh.exterior_facet_indices(domain.topology)
    dofs = fem.locate_dofs_topological(problem.V, 1, facets)
    problem.bcs = [fem.dirichletbc(linear, dofs)]
    problem.solve_displacement(0.0)
    np.testing.assert_allclose(problem.displacement.x.array, linear.x.array, atol=1e-15)
    # the cut-out's edges are boundary: the corner (0.5, 0.5) and the edge x = 0.5 above it are held
    held = problem.V.tabulate_dof_coordinates()[dofs][:, :2]
    assert (np.abs(held - [0.5, 0.75]).sum(axis=1) < 1e-12).any()


def _setup(padding="replicate"):
    grid = PixelGrid.for_scene(L_PANEL)
    return grid, SlitCuts.for_scene(L_PANEL, grid, padding), geometry.solid_pixels(L_PANEL, grid)


def _history(grid, solid):
    """A history peak at the re-entrant corner, 0 in the cut-out (no Gauss point there)."""
    x, y = grid.pixel_centres()
    xx, yy = np.meshgrid(x, y)
    peak = 3e3 * np.exp(-((xx - 0.5) ** 2 + (yy - 0.5) ** 2) / 0.01) + 5.0
    return np.where(solid, peak * (1 + 0.05 * np.random.default_rng(0).random(grid.shape)), 0.0)


def test_every_link_that_leaves_the_solid_is_cut():
    grid, cuts, solid = _setup()
    flat = solid.ravel()
    assert (flat[cuts.rows] != flat[cuts.cols]).all()            # only links between the solid and the cut-out
    pairs = set(zip(cuts.rows.tolist(), cuts.cols.tolist(), strict=True))
    assert pairs == {(j, i) for i, j in pairs}                      # both directions: symmetric
    nx = grid.nx_px
    corner_solid = 19 * nx + 20 + 0                                 # pixel (row 19, col 20): below the corner, solid
    corner_cut = 20 * nx + 20                                       # pixel (row 20, col 20): the cut-out's corner pixel
    left_of_corner = 20 * nx + 19                                   # solid, left of it
    assert solid.ravel()[corner_solid] and not solid.ravel()[corner_cut] and solid.ravel()[left_of_corner]
    # the diagonal link through the re-entrant corner (19, 19) -> (20, 20) is cut too
    assert (19 * nx + 19, corner_cut) in pairs
    # the cut Laplacian has no flux into the cut-out: a field that is 1 in the cut-out, 0 outside
    phi = (~solid).astype(float)
    lap = PixelEquation(GC, LC, grid.h_px, "replicate", cuts).residual_on(
        phi, np.zeros(grid.shape), (slice(0, grid.ny_px), slice(0, grid.nx_px)), normalised=False)
    np.testing.assert_allclose(lap[solid], 0.0, atol=1e-9)


def test_exact_solver_and_certificate_on_a_grid_with_a_cut_out():
    """The exact pixel solve equals the direct solution of the cut operator (an M-matrix with row
    sums >= Gc/lc + 2H), is 0 in the cut-out, and max |r| bounds the error of any perturbation."""
    grid, cuts, solid = _setup()
    history = _history(grid, solid)
    exact = solve_pixel_equation(history, GC, LC, grid.h_px, "replicate", rtol=1e-13, cuts=cuts)
    diffusion = GC * LC / grid.h_px**2
    system = scipy.sparse.diags(GC / LC + 2 * history.ravel()) - diffusion * (laplacian_matrix(*grid.shape, "replicate") - cuts.matrix())
    direct = scipy.sparse.linalg.spsolve(system.tocsc(), 2 * history.ravel()).reshape(grid.shape)
    np.testing.assert_allclose(exact, direct, atol=1e-9)
    assert np.abs(exact[~solid]).max() < 1e-12
    off = system - scipy.sparse.diags(system.diagonal())
    assert off.max() <= 0 and (np.asarray(system.sum(axis=1)).ravel() >= GC / LC + 2 * history.ravel() - 1e-6).all()
    assert_certificate_bounds_the_error(exact, history, GC, LC, grid.h_px, cuts)


@pytest.mark.parametrize("compiled", [True, False])
def test_the_verified_correction_reaches_the_cut_solution(compiled, monkeypatch):
    import ifenn.pixel_equation.numpy_backend as numpy_backend

    if not compiled:
        monkeypatch.setattr(numpy_backend, "compiled_kernel", lambda: None)
    elif numpy_backend.compiled_kernel() is None:
        pytest.skip("no C++ compiler: the compiled kernel is not built here")
    grid, cuts, solid = _setup()
    history = _history(grid, solid)
    exact = solve_pixel_equation(history, GC, LC, grid.h_px, "replicate", rtol=1e-13, cuts=cuts)
    equation = PixelEquation(GC, LC, grid.h_px, "replicate", cuts)
    box = (slice(0, grid.ny_px), slice(0, grid.nx_px))
    phi = 2 * history / (GC / LC + 2 * history)
    worst, iterations = equation.solve_box(phi, history, box, target=1e-6)
    assert worst <= 1e-6 and iterations > 0
    assert np.abs(phi - exact).max() <= 2e-6


@pytest.mark.parametrize("cutout, message", [
    ({"x": [0.52, 1.0], "y": [0.5, 1.0]}, "not on mesh lines"),
    ({"x": [0.5, 1.5], "y": [0.5, 1.0]}, "outside the domain"),
    ({"x": [0.0, 1.0], "y": [0.0, 1.0]}, "removes the whole domain"),
])
def test_a_cut_out_off_the_mesh_lines_is_refused(quick_config, cutout, message):
    from ifenn.config import ConfigError, validate_config

    config = copy.deepcopy(quick_config)
    config["scenes"]["panel"] = {**copy.deepcopy(L_PANEL), "cutouts": [cutout],
                                 "boundary": {"bottom": {"x": "fixed", "y": "fixed"}, "top": [{"range": [0.0, 0.25], "y": "load"}]}}
    config["fem_runs"]["panel"] = {"scene": "panel", "schedule": "I"}
    with pytest.raises(ConfigError, match=message) as info:
        validate_config(config, petsc_names=False)
    assert "config key 'scenes.panel.cutouts[0]'" in str(info.value)


def test_a_support_inside_a_cut_out_is_refused_and_the_l_panel_passes(quick_config):
    from ifenn.config import ConfigError, validate_config

    config = copy.deepcopy(quick_config)
    config["scenes"]["panel"] = copy.deepcopy(L_PANEL)
    config["fem_runs"]["panel"] = {"scene": "panel", "schedule": "I"}
    validate_config(config, petsc_names=False)
    config["scenes"]["panel"]["boundary"]["points"] = [{"at": [0.75, 0.75], "y": "load"}]
    with pytest.raises(ConfigError, match="inside a cut-out"):
        validate_config(config, petsc_names=False)


def test_an_l_panel_runs_and_the_exact_pixel_step_follows_fem(quick_config, tmp_path):
    """A quick L-panel end to end: FEM on the mesh without the quadrant, and the exact pixel
    step over the whole load path (the cut-out cut out of its operator) reach FEM's peak to 1 %
    and keep phi = 0 in the cut-out."""
    import pandas as pd

    from ifenn.config import fem_run_spec, ifenn_run_spec, validate_config
    from ifenn.fem.mesh import write_mesh
    from ifenn.fem.solver import run_fem
    from ifenn.hybrid.runs import run_ifenn
    from ifenn.run_files import read_phase_field_maps

    config = copy.deepcopy(quick_config)
    config["scenes"]["corner"] = {**copy.deepcopy(L_PANEL), "elements": [20, 20]}
    # pulled at the top, held at the leg's foot: the re-entrant corner concentrates the stress
    config["scenes"]["corner"]["boundary"] = {"bottom": {"x": "fixed", "y": "fixed"}, "top": {"y": "load"}}
    config["scenes"]["corner"]["material"] = {"lc": 0.1}        # lc/h = 2: the test's coarsest
    config["schedules"]["corner"] = [{"increments": 60, "step": 1.0e-3}]
    config["fem_runs"]["corner"] = {"scene": "corner", "schedule": "corner"}
    config["ifenn_runs"]["corner-exact"] = {"fem_run": "corner", "predictor": "exact_pixel", "smoothing_sigma": None,
                                             "switch_over": "start"}
    config = validate_config(config, petsc_names=False)
    spec = fem_run_spec(config, "corner")
    write_mesh(build_mesh(spec["scene"]), tmp_path / "mesh.xdmf")
    fem = pd.DataFrame(run_fem(spec, tmp_path / "mesh.xdmf", tmp_path / "fem", progress=False))
    exact = pd.DataFrame(run_ifenn(ifenn_run_spec(config, "corner-exact"), tmp_path / "mesh.xdmf", None, None,
                                   tmp_path / "exact", progress=False))
    assert fem.reaction_force.max() > 2 * fem.reaction_force.iloc[0] and fem.reaction_force.iloc[-1] < 0.5 * fem.reaction_force.max()
    assert exact.reaction_force.max() == pytest.approx(fem.reaction_force.max(), rel=0.01)
    maps, _ = read_phase_field_maps(tmp_path / "exact" / "fields.h5")
    solid = geometry.solid_pixels(config["scenes"]["corner"], PixelGrid.for_scene(config["scenes"]["corner"]))
    _, phi = maps[max(maps)]
    assert np.abs(phi[~solid]).max() < 1e-9 and phi[solid].max() > 0.9
    # the same panel on the adaptive mesh (the cut-out's cells left out): FEM's peak to 1 %
    from ifenn.adaptive.run import run_adaptive
    from ifenn.config import adaptive_run_spec

    config["adaptive_runs"]["corner-adaptive"] = {"fem_run": "corner"}
    config = validate_config(config, petsc_names=False)
    adaptive = pd.DataFrame(run_adaptive(adaptive_run_spec(config, "corner-adaptive"), tmp_path / "adaptive", progress=False))
    assert adaptive.reaction_force.max() == pytest.approx(fem.reaction_force.max(), rel=0.01)
    assert (adaptive.outside_fine == 0).all()


SEGMENT = {"from": [0.85, 0.5], "to": [0.95, 0.5], "y": "load"}


@pytest.mark.parametrize("segment, message", [
    ({"from": [0.5, 0.25], "to": [0.7, 0.25], "y": "load"}, "must lie on the solid's boundary"),   # inside the solid
    ({"from": [0.6, 0.75], "to": [0.7, 0.75], "y": "load"}, "must lie on the solid's boundary"),   # inside the cut-out
    ({"from": [0.6, 0.4], "to": [0.7, 0.5], "y": "load"}, "horizontal or vertical"),
    ({"from": [0.62, 0.5], "to": [0.7, 0.5], "y": "load"}, "must lie on mesh nodes"),
])
def test_a_segment_off_the_solid_boundary_is_refused(quick_config, segment, message):
    from ifenn.config import ConfigError, validate_config

    config = copy.deepcopy(quick_config)
    config["scenes"]["panel"] = copy.deepcopy(L_PANEL)
    config["scenes"]["panel"]["boundary"] = {"bottom": {"x": "fixed", "y": "fixed"}, "segments": [segment]}
    config["fem_runs"]["panel"] = {"scene": "panel", "schedule": "I"}
    with pytest.raises(ConfigError, match=message) as info:
        validate_config(config, petsc_names=False)
    assert "config key 'scenes.panel.boundary.segments[0]'" in str(info.value)
    config["scenes"]["panel"]["boundary"]["segments"] = [SEGMENT]
    validate_config(config, petsc_names=False)


def test_a_load_on_a_cut_out_edge_is_balanced_by_the_support(quick_config, tmp_path):
    """The L-panel pulled up on a short segment of its arm's lower edge (the cut-out's edge): the
    segment's nodes carry the load, and the fixed foot's reaction balances it (equilibrium)."""
    import dolfinx.fem.petsc as fem_petsc
    import ufl
    from conftest import build_problem
    from dolfinx import fem

    from ifenn.models import phase_field_model

    scene = copy.deepcopy(L_PANEL)
    scene["boundary"] = {"bottom": {"x": "fixed", "y": "fixed"}, "segments": [SEGMENT]}
    problem, _ = build_problem(scene, MATERIAL, quick_config["solver"]["linear_solver_presets"]["direct"], tmp_path)
    coordinates = problem.V.tabulate_dof_coordinates()[:, :2]
    loaded = coordinates[problem.loaded_dofs // 2]
    assert len(loaded) == 3 and np.allclose(loaded[:, 1], 0.5) and np.allclose(sorted(loaded[:, 0]), [0.85, 0.9, 0.95])
    problem.solve_displacement(1e-3)
    v = ufl.TestFunction(problem.V)
    forces = fem_petsc.assemble_vector(fem.form(phase_field_model().equilibrium_form(problem.displacement, v, problem.phase_field_gp, MATERIAL)
                                                * problem.dx)).array.reshape(-1, 2)
    foot = np.abs(coordinates[:, 1]) < 1e-12
    load = problem.reaction_force()
    assert load > 0
    assert forces[foot, 1].sum() == pytest.approx(-load, rel=1e-8)
    assert abs(forces[foot, 0].sum()) < 1e-8 * load


def test_the_l_panel_specimen_is_config_and_its_measurement_must_exist(paper_config, quick_config):
    """The paper config's L-panel: a cut-out, a segment load on its edge, plane stress, 100 mm, its
    own concrete; E and nu give the Lame pair of the published study (6.16 and 10.95 kN/mm^2); its
    measured curve lies in data/ and a missing file is refused by key."""
    from ifenn.config import ConfigError, fem_run_spec, validate_config

    material = fem_run_spec(paper_config, "l-panel")["material"]
    assert material["lame_lambda"] == pytest.approx(6161.3, rel=1e-4) and material["lame_mu"] == pytest.approx(10953.4, rel=1e-4)
    assert material["plane"] == "stress" and material["thickness"] == 100.0
    config = copy.deepcopy(quick_config)
    config["specimens"]["l-panel"]["measured"]["file"] = "data/missing.csv"
    with pytest.raises(ConfigError, match="specimens.l-panel.measured.file"):
        validate_config(config, petsc_names=False)


def test_patch_test_on_an_adaptive_mesh_with_a_cut_out():
    """The adaptive mesh leaves a cut-out's fine cells out (finest leaves, so none straddles its
    edge): uniaxial plane strain on the square without its right strip, graded with hanging nodes,
    is exact, and the removed pixels read 0."""
    from ifenn.adaptive.problem import AdaptiveMeshProblem
    from ifenn.adaptive.quadtree import build_quadtree

    scene = {"domain": {"x": [0.0, 1.0], "y": [0.0, 1.0]}, "elements": [16, 16],
             "cutouts": [{"x": [0.75, 1.0], "y": [0.0, 1.0]}],
             "boundary": {"bottom": {"y": "fixed"}, "left": {"x": "fixed"}, "top": {"y": "load"}}}
    pixels = PixelGrid.for_scene(scene)
    removed = ~geometry.solid_pixels(scene, pixels)
    target = np.zeros(pixels.shape, dtype=int)
    target[10:14, 4:9] = 3
    tree = build_quadtree(target, 3, (pixels.x0, pixels.y0), pixels.h_px, removed=removed)
    assert len(tree.hanging) > 0 and tree.points[:, 0].max() == pytest.approx(0.75)
    problem = AdaptiveMeshProblem(tree, scene, MATERIAL, {"ksp_type": "preonly", "pc_type": "lu"}, pixels)
    problem.set_phase_field(np.zeros(pixels.shape))
    problem.solve_displacement(1e-3)
    assert_uniaxial_plane_strain(problem, 1e-3, 0.75)
    psi = problem.tensile_energy()
    assert (psi[removed] == 0).all() and np.ptp(psi[~removed]) < 1e-9 * psi.max()


def test_the_l_panel_band_holds_its_own_test_and_refuses_twice_its_force(paper_config):
    """Winkler's scatter band (data/): its edges ordered, its peaks 6.7 and 7.6 kN at 0.2 mm; test
    series A (data/) peaks inside it and lies in it nearly everywhere; a curve twice as strong is out."""
    import pandas as pd

    from ifenn.config import REPO
    from ifenn.studies.tables.specimens import in_band, specimen_table

    entry = paper_config["specimens"]["l-panel"]
    band = pd.read_csv(REPO / entry["band"]["file"], comment="#")
    assert (band.load_lower_N <= band.load_upper_N).all()
    assert band.load_lower_N.max() == pytest.approx(6700) and band.load_upper_N.max() == pytest.approx(7600)
    assert band.displacement_mm[band.load_upper_N.idxmax()] == pytest.approx(0.2)
    series = pd.read_csv(REPO / entry["measured"]["file"], comment="#")
    own = in_band(series.displacement_mm, series.load_N, band)
    assert own["peak_in_band"] and own["in_band_fraction"] >= 0.95
    twice = in_band(series.displacement_mm, 2 * series.load_N, band)
    assert not twice["peak_in_band"] and twice["in_band_fraction"] < 0.1
    table = specimen_table({"twice": pd.DataFrame({"u": series.displacement_mm, "reaction_force": 2 * series.load_N})},
                           series, band).set_index("run")
    assert table.loc["measured", "peak_in_band"] and not table.loc["twice", "peak_in_band"]
