"""Slit meshes: node counts, snapping, and twins that separate under load."""

import numpy as np
import pytest

from ifenn.fem.mesh import build_mesh, element_size


def test_snt1_node_count_matches_the_published_mesh(paper_config):
    mesh = build_mesh(paper_config["scenes"]["snt1"])
    assert mesh.n_grid_nodes == 201 * 201
    assert len(mesh.points) == 201 * 201 + 60  # the authors' mesh: 60 duplicated nodes
    assert mesh.cells.shape == (40000, 4)


def test_interior_slit_keeps_both_tips_shared():
    scene = {"domain": {"x": [0, 1], "y": [0, 1]}, "elements": [10, 10], "boundary": {},
             "notches": [{"kind": "slit", "start": [0.2, 0.5], "end": [0.7, 0.5]}]}
    mesh = build_mesh(scene)
    assert len(mesh.points) - mesh.n_grid_nodes == 4  # x = 0.3 .. 0.6, tips at 0.2 and 0.7 shared
    twins = mesh.points[mesh.n_grid_nodes:]
    np.testing.assert_allclose(twins[:, 1], 0.5)
    np.testing.assert_allclose(np.sort(twins[:, 0]), [0.3, 0.4, 0.5, 0.6])
    # every twin is used by exactly the two cells above the slit, its original by the two below
    for twin in range(mesh.n_grid_nodes, len(mesh.points)):
        users = np.nonzero((mesh.cells == twin).any(axis=1))[0]
        assert len(users) == 2
        centroids = mesh.points[mesh.cells[users]].mean(axis=1)
        assert (centroids[:, 1] > 0.5).all()


def test_vertical_slit_and_snapping(paper_config):
    mesh = build_mesh(paper_config["scenes"]["adnt"])
    assert len(mesh.points) - mesh.n_grid_nodes == 40  # two 0.1 mm slits from the edges, h = 0.005
    snt2 = build_mesh(paper_config["scenes"]["snt2"])
    h = element_size(paper_config["scenes"]["snt2"])
    tip = snt2.slits[0]["snapped"][1][0]
    assert abs(tip - (-0.2)) <= h / 2 and abs((tip + 0.5) / h - round((tip + 0.5) / h)) < 1e-9


def test_a_slit_between_mesh_lines_is_refused_unless_it_may_snap(quick_config):
    """A slit whose tip falls between mesh lines is refused before any job, naming the key; with
    ``snap: true`` it moves to the nearest line, and the mesh says where."""
    import copy

    from ifenn.config import ConfigError, validate_config

    config = copy.deepcopy(quick_config)
    scene = config["scenes"]["slitted"] = copy.deepcopy(config["scenes"]["snt1"])
    h = element_size(scene)
    scene["notches"] = [{"kind": "slit", "start": [-0.5, 0.0], "end": [-0.2 + 0.3 * h, 0.0]}]
    with pytest.raises(ConfigError, match="between mesh lines") as info:
        validate_config(config, petsc_names=False)
    assert "config key 'scenes.slitted.notches[0]'" in str(info.value) and "snap: true" in str(info.value)
    with pytest.raises(ValueError, match="between mesh lines"):
        build_mesh(scene)
    scene["notches"][0]["snap"] = True
    validate_config(config, petsc_names=False)
    tip = build_mesh(scene).slits[0]["snapped"][1][0]
    assert abs(tip - (-0.2)) < 1e-12  # 0.3 h off: to the nearest line


def test_crossing_slits_are_rejected():
    scene = {"domain": {"x": [0, 1], "y": [0, 1]}, "elements": [10, 10], "boundary": {},
             "notches": [{"kind": "slit", "start": [0.0, 0.5], "end": [0.6, 0.5]},
                         {"kind": "slit", "start": [0.5, 0.0], "end": [0.5, 0.6]}]}
    with pytest.raises(ValueError, match="another slit"):
        build_mesh(scene)


def test_non_square_elements_are_rejected():
    with pytest.raises(ValueError, match="square"):
        element_size({"domain": {"x": [0, 1], "y": [0, 1]}, "elements": [10, 20]})
