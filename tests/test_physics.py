"""Physics checks of the FEM building blocks on small scenes: patch test, the analytic
AT2 profile, the homogeneous phase-field solution, the pixel map, separating slit faces."""

import numpy as np
import pytest
from conftest import build_problem

from ifenn.fem.phase_field import FEMPhaseField


def _material(paper_config, **changes):
    return {**paper_config["material"], **changes}


def test_patch_uniaxial_stress_reaction_and_history_are_exact(paper_config, tmp_path):
    """Uniform strain (rollers bottom/left, top pulled, right free), phi = 0: the reaction is
    sigma_yy * width with sigma_yy = 4 mu (lambda + mu)/(lambda + 2 mu) * eps_yy (plane
    strain, sigma_xx = 0), and H equals psi0+ of that strain at every Gauss point."""
    scene = {"domain": {"x": [0.0, 2.0], "y": [0.0, 1.0]}, "elements": [8, 4], "notches": [],
             "boundary": {"bottom": {"y": "fixed"}, "left": {"x": "fixed"}, "top": {"y": "load"}}}
    material = _material(paper_config)
    lam, mu = material["lame_lambda"], material["lame_mu"]
    problem, _ = build_problem(scene, material, paper_config["solver"]["linear_solver_presets"]["direct"], tmp_path)
    u = 1.0e-3
    problem.solve_displacement(u)
    problem.update_history()
    eps_yy = u / 1.0
    sigma_yy = 4 * mu * (lam + mu) / (lam + 2 * mu) * eps_yy
    assert problem.reaction_force() == pytest.approx(sigma_yy * 2.0, rel=1e-9)
    eps_xx = -lam / (lam + 2 * mu) * eps_yy
    psi_plus = 0.5 * lam * (eps_xx + eps_yy) ** 2 + mu * eps_yy**2  # eps_xx < 0 drops out of eps+
    np.testing.assert_allclose(problem.history.x.array, psi_plus, rtol=1e-9)


def test_compression_creates_no_history(paper_config, tmp_path):
    """Spectral split: uniaxial compression leaves only the lateral (positive) strain in psi0+."""
    scene = {"domain": {"x": [0.0, 1.0], "y": [0.0, 1.0]}, "elements": [4, 4], "notches": [],
             "boundary": {"bottom": {"y": "fixed"}, "left": {"x": "fixed"}, "top": {"y": "load"}}}
    material = _material(paper_config)
    lam, mu = material["lame_lambda"], material["lame_mu"]
    problem, _ = build_problem(scene, material, paper_config["solver"]["linear_solver_presets"]["direct"], tmp_path)
    problem.solve_displacement(-1.0e-3)
    problem.update_history()
    eps_xx = lam / (lam + 2 * mu) * 1.0e-3  # lateral expansion
    np.testing.assert_allclose(problem.history.x.array, mu * eps_xx**2, rtol=1e-9)


def _strip_problem(paper_config, tmp_path, lc, lc_over_h):
    h = lc / lc_over_h
    n = int(round(1.0 / h))
    scene = {"domain": {"x": [-0.5, 0.5], "y": [0.0, 4 * h]}, "elements": [n, 4], "notches": [],
             "boundary": {"bottom": {"y": "load"}}}
    material = _material(paper_config, lc=lc)
    petsc = paper_config["solver"]["linear_solver_presets"]["direct"]
    problem, _ = build_problem(scene, material, petsc, tmp_path, name=f"strip{lc_over_h}")
    return problem, FEMPhaseField(problem, petsc["phase_field"]), h


@pytest.mark.parametrize("lc_over_h", [4, 6])
def test_fully_cracked_band_gives_the_1d_at2_profile(paper_config, tmp_path, lc_over_h):
    """H >> Gc/lc in a band at x = 0 and 0 elsewhere: phi = exp(-|x - x_b|/lc) outside the
    band (AT2). The fitted decay length must be within 5 % of lc."""
    lc = 0.05
    problem, step, h = _strip_problem(paper_config, tmp_path, lc, lc_over_h)
    gp_x = problem.gauss_point_coordinates[..., 0]
    values = np.zeros_like(problem.history.x.array)
    values[problem.q_dofs] = np.where(np.abs(gp_x) < h, 1.0e8, 0.0)
    problem.history.x.array[:] = values
    step.solve()
    x = problem.W.tabulate_dof_coordinates()[:, 0]
    phi = problem.phase_field.x.array
    assert phi[np.abs(x) < 1e-12].min() > 0.99
    fit = (np.abs(x) > 2 * lc) & (np.abs(x) < 6 * lc)
    slope = np.polyfit(np.abs(x[fit]), np.log(phi[fit]), 1)[0]
    print(f"lc/h = {lc_over_h}: fitted decay length {-1.0 / slope:.5f} mm, lc = {lc}")
    assert -1.0 / slope == pytest.approx(lc, rel=0.05)


def test_homogeneous_history_gives_the_local_solution(paper_config, tmp_path):
    """Uniform H: the Laplacian vanishes and phi = 2H / (Gc/lc + 2H) exactly."""
    problem, step, _ = _strip_problem(paper_config, tmp_path, 0.05, 4)
    Gc, lc, H = paper_config["material"]["Gc"], 0.05, 37.0
    problem.history.x.array[:] = H
    step.solve()
    np.testing.assert_allclose(problem.phase_field.x.array, 2 * H / (Gc / lc + 2 * H), rtol=1e-8)
    np.testing.assert_allclose(problem.phase_field_gp.x.array, 2 * H / (Gc / lc + 2 * H), rtol=1e-8)


def test_gauss_point_pixel_map_is_one_to_one_and_inverse(quick_config, tmp_path):
    scene = quick_config["scenes"]["adnt"]  # a rectangle with slits
    material = quick_config["material"]
    problem, _ = build_problem(scene, material, quick_config["solver"]["linear_solver_presets"]["iterative"], tmp_path)
    image = np.random.default_rng(0).random(problem.pixels.shape)
    assert image.shape == (2 * scene["elements"][1], 2 * scene["elements"][0])
    problem.gauss_points_from_pixels(image, problem.history)
    np.testing.assert_array_equal(problem.pixels_from_gauss_points(problem.history), image)
    # every Gauss point lies inside its pixel (row 0 = bottom of the domain)
    coords = problem.gauss_point_coordinates.reshape(-1, 2)
    pix = problem.pixel_of_q_dof[problem.q_dofs.ravel()]
    xc, yc = problem.pixels.pixel_centres()
    iy, ix = np.divmod(pix, problem.pixels.nx_px)
    assert np.abs(coords[:, 0] - xc[ix]).max() < problem.pixels.h_px / 2
    assert np.abs(coords[:, 1] - yc[iy]).max() < problem.pixels.h_px / 2
    assert len(np.unique(pix)) == image.size


def test_history_notch_sets_the_borden_initial_history(paper_config, tmp_path):
    """A 'history' notch: H0 = B Gc/(2 lc) (1 - 4d/lc) within lc/4 of the segment, 0 beyond."""
    lc = 0.05
    scene = {"domain": {"x": [0.0, 1.0], "y": [0.0, 1.0]}, "elements": [80, 80],
             "notches": [{"kind": "history", "start": [0.0, 0.503], "end": [0.4, 0.503]}],
             "boundary": {"bottom": {"x": "fixed", "y": "fixed"}, "top": {"y": "load"}}}
    material = _material(paper_config, lc=lc)
    problem, _ = build_problem(scene, material, paper_config["solver"]["linear_solver_presets"]["direct"], tmp_path)
    x = problem.gauss_point_coordinates.reshape(-1, 2)
    h0 = problem.history.x.array[problem.q_dofs.ravel()]
    d = np.where(x[:, 0] <= 0.4, np.abs(x[:, 1] - 0.503), np.hypot(x[:, 0] - 0.4, x[:, 1] - 0.503))
    expected = np.where(d <= lc / 4, material["history_notch_B"] * material["Gc"] / (2 * lc) * (1 - 4 * d / lc), 0.0)
    np.testing.assert_allclose(h0, expected, rtol=1e-12, atol=1e-9)
    assert (h0 > 0).sum() > 100 and h0.max() > 0.5 * material["history_notch_B"] * material["Gc"] / (2 * lc)
