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


def assert_uniaxial_plane_strain(problem, strain: float, width: float) -> None:
    """A problem held at y = 0 in y and x = 0 in x, pulled to u_y = strain y at the top, has the
    linear uniaxial plane-strain field at every node (hanging ones included) and the analytic force
    (lambda + 2 mu - lambda^2 / (lambda + 2 mu)) strain width on the top edge."""
    import numpy as np
    import pytest

    lam, mu = problem.material["lame_lambda"], problem.material["lame_mu"]
    u = problem.displacement.x.array.reshape(-1, 2)
    x = problem.V.tabulate_dof_coordinates()[:, :2]
    np.testing.assert_allclose(u[:, 1], strain * x[:, 1], atol=1e-14)
    np.testing.assert_allclose(u[:, 0], -lam / (lam + 2 * mu) * strain * x[:, 0], atol=1e-14)
    assert problem.reaction_force() == pytest.approx((lam + 2 * mu - lam**2 / (lam + 2 * mu)) * strain * width, rel=1e-10)


def assert_certificate_bounds_the_error(exact, history, Gc, lc, h_px, cuts, seed=2) -> None:
    """max |r| (normalised, with the cuts) bounds max |phi - exact| for perturbations of three sizes."""
    import numpy as np

    from ifenn.pixel_equation.numpy_backend import normalised_residual

    rng = np.random.default_rng(seed)
    for scale in (1e-3, 1e-2, 0.1):
        phi = exact + scale * rng.standard_normal(exact.shape)
        bound = np.abs(normalised_residual(phi, history, Gc, lc, h_px, "replicate", cuts)).max()
        assert np.abs(phi - exact).max() <= bound * (1 + 1e-9)
