"""Shared fixtures: the repository's configs and small scenes built in a temporary folder."""

from __future__ import annotations

import copy
import logging
from pathlib import Path

import pytest

from ifenn.config import fem_run_spec, load_config

REPO = Path(__file__).resolve().parents[1]
for noisy in ("ffcx", "UFL", "root", "compilers"):
    logging.getLogger(noisy).setLevel(logging.WARNING)


@pytest.fixture(scope="session")
def paper_config():
    return load_config(REPO / "config" / "config.yaml")


@pytest.fixture(scope="session")
def quick_config():
    return load_config(REPO / "config" / "config.yaml", REPO / "config" / "quick.yaml")


@pytest.fixture
def quick_spec(quick_config):
    def make(run="snt1-I", **overrides):
        spec = copy.deepcopy(fem_run_spec(quick_config, run))
        spec.update(overrides)
        return spec

    return make


def quick_fem_run(quick_config, tmp_path_factory, run: str, folder: str):
    """A FEM run of the quick config, meshed and run in a temporary folder: (spec, folder, history)."""
    import pandas as pd

    from ifenn.fem.mesh import build_mesh, write_mesh
    from ifenn.fem.solver import run_fem

    tmp = tmp_path_factory.mktemp(folder)
    spec = fem_run_spec(quick_config, run)
    write_mesh(build_mesh(spec["scene"]), tmp / "mesh.xdmf")
    history = pd.DataFrame(run_fem(spec, tmp / "mesh.xdmf", tmp / "fem", progress=False))
    return spec, tmp, history


def build_problem(scene, material, petsc, tmp_path, name="scene"):
    """Mesh ``scene`` through the real path (meshio XDMF -> dolfinx) and set up the problem."""
    from ifenn.fem.mesh import build_mesh, read_dolfinx_mesh, write_mesh
    from ifenn.fem.problem import FractureProblem

    path = Path(tmp_path) / f"{name}.xdmf"
    write_mesh(build_mesh(scene), path)
    domain = read_dolfinx_mesh(path)
    return FractureProblem(domain, scene, material, petsc), path
