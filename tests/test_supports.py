"""Supports and loads on part of an edge and on single nodes: the config refuses what the mesh
cannot hold or what leaves a rigid-body motion free, and a simply supported beam's reactions obey
statics on the uniform and on the adaptive mesh."""

from __future__ import annotations

import copy

import numpy as np
import pytest

from ifenn.fem.supports import conditions, problems, rigid_body_motions_left

# a 2 x 0.5 mm beam on 16 x 4 elements (h = 0.125): pinned at the bottom left corner, a roller at
# the bottom right one, pulled up on the middle quarter of its top edge
BEAM = {"domain": {"x": [-1.0, 1.0], "y": [-0.25, 0.25]}, "elements": [16, 4],
        "boundary": {"top": [{"range": [-0.25, 0.25], "y": "load"}],
                     "points": [{"at": [-1.0, -0.25], "x": "fixed", "y": "fixed"}, {"at": [1.0, -0.25], "y": "fixed"}]}}
MATERIAL = {"lame_lambda": 121154.0, "lame_mu": 80770.0, "Gc": 2.7, "lc": 0.03, "residual_stiffness": 0.0,
            "history_notch_B": 1e3}


def _with(boundary: dict) -> dict:
    scene = copy.deepcopy(BEAM)
    scene["boundary"] = boundary
    return scene


def test_whole_edges_parts_and_points_select_their_nodes():
    x = np.linspace(-1, 1, 17)
    found = {c.key: c for c in conditions(BEAM, "scenes.beam")}
    top = found["scenes.beam.boundary.top[0]"]
    assert top.kind == "load" and top.component == 1
    np.testing.assert_array_equal(top.selects(x, np.full(17, 0.25)), np.abs(x) <= 0.25 + 1e-12)
    assert not top.selects(np.array([0.0]), np.array([0.125]))[0]          # not below the edge
    pin = [c for c in conditions(BEAM) if c.is_point and c.start == (-1.0, -0.25)]
    assert sorted(c.component for c in pin) == [0, 1]
    whole = conditions(_with({"bottom": {"x": "fixed", "y": "fixed"}, "top": {"y": "load"}}))
    assert all(c.start[0] == -1.0 and c.end[0] == 1.0 for c in whole)
    assert problems(BEAM, "scenes.beam") == []


@pytest.mark.parametrize("boundary, message", [
    # a roller alone: the beam slides and turns
    ({"top": {"y": "load"}, "points": [{"at": [1.0, -0.25], "y": "fixed"}]}, "rigid-body motion free (x translation"),
    # two rollers in y: nothing holds x
    ({"top": [{"range": [-0.25, 0.25], "y": "load"}],
      "points": [{"at": [-1.0, -0.25], "y": "fixed"}, {"at": [1.0, -0.25], "y": "fixed"}]}, "x translation"),
    # every x held on one vertical line: it may still turn about nothing else... held: left edge x only
    ({"left": {"x": "fixed"}, "right": {"x": "load"}}, "y translation"),
    ({"top": [{"range": [-0.3, 0.25], "y": "load"}], "bottom": {"x": "fixed", "y": "fixed"}}, "must lie on mesh nodes"),
    ({"top": [{"range": [0.5, 1.5], "y": "load"}], "bottom": {"x": "fixed", "y": "fixed"}}, "within the edge"),
    ({"top": {"y": "load"}, "points": [{"at": [0.1, -0.25], "x": "fixed", "y": "fixed"}]}, "is not a mesh node"),
    ({"top": {"y": "load"}, "points": [{"at": [3.0, -0.25], "x": "fixed", "y": "fixed"}]}, "outside the domain"),
    ({"bottom": {"x": "fixed", "y": "fixed"}}, "no support prescribes 'load'"),
])
def test_refused_before_any_job_naming_the_key(boundary, message):
    found = problems(_with(boundary), "scenes.beam")
    assert found and "config key 'scenes.beam.boundary" in found[0] and message in " ".join(found), found


def test_rigid_body_motions_named():
    pinned = [c for c in conditions(BEAM) if c.is_point and c.start == (-1.0, -0.25)]
    assert rigid_body_motions_left(pinned) == ["a rotation"]
    assert rigid_body_motions_left(conditions(BEAM)) == []
    assert len(rigid_body_motions_left([])) == 3


def test_config_refuses_a_scene_whose_supports_leave_it_free(quick_config):
    from ifenn.config.checks import semantic_problems
    from ifenn.schema import load_schema

    config = copy.deepcopy(quick_config)
    config["scenes"]["snt1"]["boundary"] = {"top": {"y": "load"}}
    found = semantic_problems(config, load_schema(), petsc_names=False)
    assert any("config key 'scenes.snt1.boundary'" in p and "rigid-body motion" in p for p in found), found


def _support_reactions(forces: np.ndarray, coordinates: np.ndarray) -> dict:
    """Reactions (N/mm) at the two bottom corners and on the loaded top part, from the internal force
    vector (nodes x 2) at the nodes' coordinates."""
    x, y = coordinates[:, 0], coordinates[:, 1]
    pin = (np.abs(x + 1) < 1e-9) & (np.abs(y + 0.25) < 1e-9)
    roller = (np.abs(x - 1) < 1e-9) & (np.abs(y + 0.25) < 1e-9)
    loaded = (np.abs(y - 0.25) < 1e-9) & (np.abs(x) <= 0.25 + 1e-9)
    free = ~(pin | roller | loaded)
    return {"pin": forces[pin].sum(axis=0), "roller": forces[roller].sum(axis=0),
            "load": forces[loaded].sum(axis=0), "moment": np.sum(x * forces[:, 1] - y * forces[:, 0]),
            "free_residual": np.abs(forces[free]).max()}


def _check_statics(reactions: dict, reported: float):
    load = reactions["load"][1]
    assert reported == pytest.approx(load, rel=1e-9) and load > 0
    scale = abs(load)
    assert reactions["free_residual"] < 1e-8 * scale
    # a simply supported beam loaded at mid-span: each support carries half, the pin no x force
    assert reactions["pin"][1] == pytest.approx(-load / 2, rel=1e-8)
    assert reactions["roller"][1] == pytest.approx(-load / 2, rel=1e-8)
    assert abs(reactions["pin"][0]) < 1e-8 * scale and abs(reactions["roller"][0]) < 1e-8 * scale
    assert abs(reactions["moment"]) < 1e-8 * scale


def test_reactions_of_a_simply_supported_beam_on_the_uniform_mesh(quick_config, tmp_path):
    """Equilibrium: the force reported on the loaded part equals minus the supports' reactions,
    half at each support, with no horizontal reaction and no net moment (phi = 0, one solve)."""
    import dolfinx.fem.petsc as fem_petsc
    import ufl
    from conftest import build_problem
    from dolfinx import fem

    from ifenn.models import phase_field_model

    presets = quick_config["solver"]["linear_solver_presets"]
    problem, _ = build_problem(BEAM, MATERIAL, presets["direct"], tmp_path, "beam")
    problem.solve_displacement(1e-3)
    v = ufl.TestFunction(problem.V)
    form = fem.form(phase_field_model().equilibrium_form(problem.displacement, v, problem.phase_field_gp, MATERIAL) * problem.dx)
    forces = fem_petsc.assemble_vector(form).array.reshape(-1, 2)
    reactions = _support_reactions(forces, problem.V.tabulate_dof_coordinates()[:, :2])
    _check_statics(reactions, problem.reaction_force())


def test_reactions_of_a_simply_supported_beam_on_the_adaptive_mesh():
    """The same statics on a graded quadtree whose coarse cells would miss the load's ends: the
    adaptive run makes the ends of parts and the points nodes (supports.anchor_cells)."""
    from ifenn.adaptive.problem import AdaptiveMeshProblem
    from ifenn.adaptive.quadtree import build_quadtree
    from ifenn.fem.supports import anchor_cells
    from ifenn.pixels import PixelGrid

    pixels = PixelGrid.for_scene(BEAM)
    h_fine = pixels.h_px
    target = np.zeros(pixels.shape, dtype=int)
    target[2:5, 6:9] = target[2:5, 23:26] = 2                  # refinement off the supports, mirror-symmetric
    target[anchor_cells(BEAM, (pixels.x0, pixels.y0), h_fine, pixels.shape)] = 2
    tree = build_quadtree(target, 2, (pixels.x0, pixels.y0), h_fine)
    assert (tree.cell_size > 1).any()
    problem = AdaptiveMeshProblem(tree, BEAM, MATERIAL, {"ksp_type": "preonly", "pc_type": "lu"}, pixels)
    problem.set_phase_field(np.zeros(pixels.shape))
    problem.solve_displacement(1e-3)
    forces = (problem.P_scipy.T @ problem.internal_force_full()).reshape(-1, 2)
    reactions = _support_reactions(forces, problem.free_coordinates)
    _check_statics(reactions, problem.reaction_force())


def test_the_scene_picture_draws_parts_and_points(tmp_path):
    from ifenn.fem.mesh import build_mesh
    from ifenn.studies.figures import mesh_figure

    mesh_figure(build_mesh(BEAM), BEAM, "beam", tmp_path / "beam.png")
    assert (tmp_path / "beam.png").stat().st_size > 10_000


def test_the_schema_takes_parts_and_points_and_the_run_spec_carries_them(quick_config):
    """A scene with a loaded part and point supports passes the schema and the checks, and its
    FEM run's spec holds them; a misspelt key is refused by name."""
    from ifenn.config import ConfigError, fem_run_spec, validate_config

    config = copy.deepcopy(quick_config)
    config["scenes"]["beam"] = copy.deepcopy(BEAM)
    config["scenes"]["beam"]["elements"] = [32, 8]     # lc/h = 2.4 with the quick lc
    config["fem_runs"]["beam"] = {"scene": "beam", "schedule": "I"}
    checked = validate_config(config, petsc_names=False)
    assert fem_run_spec(checked, "beam")["scene"]["boundary"]["points"][1] == {"at": [1.0, -0.25], "y": "fixed"}
    config["scenes"]["beam"]["boundary"]["top"][0]["rnage"] = [0, 1]
    with pytest.raises(ConfigError, match="scenes.beam.boundary"):
        validate_config(config, petsc_names=False)
