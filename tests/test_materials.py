"""A material, a plane and a thickness per scene: plane stress against the analytic uniaxial
stress on the uniform and the adaptive mesh, the split's tensile energy with the condensed
out-of-plane strain, E and nu against the Lame pair, and what the config refuses."""

from __future__ import annotations

import copy

import numpy as np
import pandas as pd
import pytest

from ifenn.config import ConfigError, fem_run_spec, validate_config
from ifenn.materials import scene_material

E, NU, THICKNESS = 25850.0, 0.18, 100.0
SQUARE = {"domain": {"x": [0.0, 1.0], "y": [0.0, 1.0]}, "elements": [8, 8],
          "boundary": {"bottom": {"y": "fixed"}, "left": {"x": "fixed"}, "top": {"y": "load"}},
          "plane": "stress", "thickness": THICKNESS, "material": {"E": E, "nu": NU, "Gc": 0.09, "lc": 0.5}}
BASE = {"lame_lambda": 121154.0, "lame_mu": 80770.0, "Gc": 2.7, "lc": 0.03, "residual_stiffness": 0.0,
        "history_notch_B": 1e3}
STRAIN = 1e-4


def test_e_and_nu_give_the_lame_pair_and_a_scene_without_its_own_keeps_the_config_material():
    material = scene_material(BASE, SQUARE)
    mu, lam = material["lame_mu"], material["lame_lambda"]
    assert mu * (3 * lam + 2 * mu) / (lam + mu) == pytest.approx(E, rel=1e-12)       # Young's modulus
    assert lam / (2 * (lam + mu)) == pytest.approx(NU, rel=1e-12)                      # Poisson's ratio
    assert material["Gc"] == 0.09 and material["plane"] == "stress" and material["thickness"] == THICKNESS
    assert scene_material(BASE, {"domain": {}, "boundary": {}}) == BASE


def _uniaxial(problem, coordinates, displacement):
    """The uniaxial plane-stress field: u_y = eps y, u_x = -nu eps x, sigma_yy = E eps."""
    np.testing.assert_allclose(displacement[:, 1], STRAIN * coordinates[:, 1], atol=1e-14)
    np.testing.assert_allclose(displacement[:, 0], -NU * STRAIN * coordinates[:, 0], atol=1e-14)
    # the force on the 1 mm top edge of a THICKNESS-thick plate
    assert problem.reaction_force() == pytest.approx(E * STRAIN * 1.0 * THICKNESS, rel=1e-10)


def _tensile_energy_uniaxial():
    """psi+ of uniaxial stress: principal strains eps, -nu eps (in plane), -nu eps (out of plane);
    the trace (1 - 2 nu) eps > 0, so psi+ = lambda/2 ((1 - 2 nu) eps)^2 + mu eps^2 (and psi- = 2 mu nu^2
    eps^2: the two add up to E eps^2 / 2)."""
    material = scene_material(BASE, SQUARE)
    lam, mu = material["lame_lambda"], material["lame_mu"]
    positive = 0.5 * lam * ((1 - 2 * NU) * STRAIN) ** 2 + mu * STRAIN**2
    assert positive + 2 * mu * NU**2 * STRAIN**2 == pytest.approx(0.5 * E * STRAIN**2, rel=1e-12)
    return positive


def test_plane_stress_uniaxial_on_the_uniform_mesh(quick_config, tmp_path):
    from conftest import build_problem

    material = scene_material(BASE, SQUARE)
    problem, _ = build_problem(SQUARE, material, quick_config["solver"]["linear_solver_presets"]["direct"], tmp_path)
    problem.solve_displacement(STRAIN)
    coordinates = problem.V.tabulate_dof_coordinates()[:, :2]
    _uniaxial(problem, coordinates, problem.displacement.x.array.reshape(-1, 2))
    problem.update_history()
    np.testing.assert_allclose(problem.history.x.array, _tensile_energy_uniaxial(), rtol=1e-9)


def test_plane_stress_uniaxial_on_the_adaptive_mesh():
    from ifenn.adaptive.problem import AdaptiveMeshProblem
    from ifenn.adaptive.quadtree import build_quadtree
    from ifenn.pixels import PixelGrid

    pixels = PixelGrid.for_scene(SQUARE)
    target = np.zeros(pixels.shape, dtype=int)
    target[5:8, 3:6] = 2
    tree = build_quadtree(target, 2, (pixels.x0, pixels.y0), pixels.h_px)
    problem = AdaptiveMeshProblem(tree, SQUARE, scene_material(BASE, SQUARE), {"ksp_type": "preonly", "pc_type": "lu"}, pixels)
    problem.set_phase_field(np.zeros(pixels.shape))
    problem.solve_displacement(STRAIN)
    _uniaxial(problem, problem.V.tabulate_dof_coordinates()[:, :2], problem.displacement.x.array.reshape(-1, 2))
    np.testing.assert_allclose(problem.tensile_energy(), _tensile_energy_uniaxial(), rtol=1e-9)


def test_plane_strain_stays_the_default(quick_config, tmp_path):
    """Without plane and thickness the force per mm is plane strain's E/(1 - nu^2) eps."""
    from conftest import build_problem

    scene = {k: v for k, v in SQUARE.items() if k not in ("plane", "thickness")}
    problem, _ = build_problem(scene, scene_material(BASE, scene), quick_config["solver"]["linear_solver_presets"]["direct"], tmp_path)
    problem.solve_displacement(STRAIN)
    assert problem.reaction_force() == pytest.approx(E / (1 - NU**2) * STRAIN, rel=1e-10)


@pytest.fixture
def with_panel(quick_config):
    config = copy.deepcopy(quick_config)
    config["scenes"]["panel"] = copy.deepcopy(SQUARE)
    config["scenes"]["panel"]["elements"] = [16, 16]
    config["fem_runs"]["panel"] = {"scene": "panel", "schedule": "I"}
    return config


def test_a_run_of_the_scene_carries_its_material(with_panel):
    spec = fem_run_spec(validate_config(with_panel, petsc_names=False), "panel")
    assert spec["material"]["plane"] == "stress" and spec["material"]["Gc"] == 0.09
    # the paper's runs resolve to the config's material, key for key (their specs and hashes stay)
    assert fem_run_spec(validate_config(with_panel, petsc_names=False), "snt1-I")["material"] == with_panel["material"]


@pytest.mark.parametrize("material, message", [
    ({"E": E}, "give E and nu together"),
    ({"E": E, "nu": NU, "lame_mu": 1.0}, "either E and nu or lame_lambda and lame_mu"),
    ({"lame_mu": 1.0}, "lame_lambda and lame_mu together"),
])
def test_a_scene_material_is_refused_naming_the_key(with_panel, material, message):
    with_panel["scenes"]["panel"]["material"] = material
    with pytest.raises(ConfigError, match=message) as info:
        validate_config(with_panel, petsc_names=False)
    assert "scenes.panel.material" in str(info.value)


def test_the_network_serves_another_material_at_its_lc_over_h_and_is_refused_elsewhere_unless_verified(with_panel):
    """Another material at the network's lc/h_px: served (its input scaled); at another lc/h_px an
    unverified run is refused by key, a verified one runs the certified pixel step without it."""
    with_panel["ifenn_runs"]["panel"] = {"fem_run": "panel"}
    with pytest.raises(ConfigError, match="ifenn_runs.panel': the network was trained on Gc 2.7, lc 0.15 at lc/h 6"):
        validate_config(with_panel, petsc_names=False)
    with_panel["ifenn_runs"]["panel"] = {"fem_run": "panel", "verification": {"enabled": True}}
    validate_config(with_panel, petsc_names=False)
    with_panel["ifenn_runs"]["panel"] = {"fem_run": "panel"}
    with_panel["scenes"]["panel"]["elements"] = [12, 12]        # lc/h = 0.5 / (1/12) = 6, the network's
    validate_config(with_panel, petsc_names=False)


def test_the_pixel_equation_depends_on_the_material_through_h_lc_over_gc_and_lc_over_h():
    """The identity the network's service rests on: the pixel solution for (Gc, lc, h) and H equals
    the one for (Gc', lc', h') and H (lc / Gc) / (lc' / Gc') when lc / h = lc' / h'."""
    from ifenn.pixel_equation.numpy_backend import solve_pixel_equation

    rng = np.random.default_rng(0)
    x = np.linspace(-1, 1, 48)
    history = 300.0 * np.exp(-(x[None, :] ** 2 + x[:, None] ** 2) / 0.05) * (1 + 0.1 * rng.random((48, 48)))
    phi = solve_pixel_equation(history, 0.089, 10.0, 10.0 / 6, "replicate", rtol=1e-13)
    scale = (10.0 / 0.089) / (0.15 / 2.7)
    same = solve_pixel_equation(history * scale, 2.7, 0.15, 0.15 / 6, "replicate", rtol=1e-13)
    np.testing.assert_allclose(phi, same, atol=1e-10)
    assert phi.max() > 0.3


def test_network_service_scales_or_falls_back(tmp_path):
    import torch

    from ifenn.hybrid.runs import ScaledHistory, network_service
    from ifenn.network.picnn import PICNN, save_picnn

    torch.manual_seed(0)
    model = tmp_path / "model.pt"
    save_picnn(PICNN(padding="replicate"), model, 0.0125, 2.7, 0.15, "test")          # lc / h_px = 12
    spec = {"predictor": "picnn", "material": {"Gc": 2.7, "lc": 0.15}}
    assert network_service(spec, model, 0.0125) == {"history_scale": 1.0, "fallback": None}
    assert network_service(spec, model, 0.05)["fallback"] is None                      # its own material: as published
    other = {"predictor": "picnn", "material": {"Gc": 0.089, "lc": 10.0}}
    served = network_service(other, model, 10.0 / 12)
    assert served["fallback"] is None and served["history_scale"] == pytest.approx((10.0 / 0.089) / (0.15 / 2.7))
    assert "lc/h_px = 12" in network_service(other, model, 1.0)["fallback"]
    seen = []
    wrapped = ScaledHistory(type("Inference", (), {"__call__": lambda self, h: seen.append(h) or h, "t_network": 1.5})(), 3.0)
    wrapped(np.ones(2))
    assert seen[0].tolist() == [3.0, 3.0] and wrapped.t_network == 1.5


def test_a_verified_run_on_another_material_is_certified_and_tracks_its_fem(quick_config, tmp_path):
    """The quick snt1 with half the toughness (lc/h the network's): the verified step, fed the scaled
    H, keeps every increment certified and follows FEM of that material; provenance says how."""
    import torch

    from ifenn.config import IFENN_OPTIONS
    from ifenn.fem.mesh import build_mesh, write_mesh
    from ifenn.fem.solver import run_fem
    from ifenn.hybrid.runs import run_ifenn
    from ifenn.network.picnn import PICNN, InputScaling, save_picnn
    from ifenn.run_files import read_provenance

    spec = copy.deepcopy(fem_run_spec(quick_config, "snt1-I"))
    spec["material"]["Gc"] = 1.35
    write_mesh(build_mesh(spec["scene"]), tmp_path / "mesh.xdmf")
    fem = pd.DataFrame(run_fem(spec, tmp_path / "mesh.xdmf", tmp_path / "fem", progress=False))
    torch.manual_seed(0)
    model = tmp_path / "model.pt"
    h_px = (spec["scene"]["domain"]["x"][1] - spec["scene"]["domain"]["x"][0]) / spec["scene"]["elements"][0] / 2
    save_picnn(PICNN(padding="replicate", input_scaling=InputScaling("log", 0.01, 45.0), init_gain=2.0).eval(), model, h_px,
               2.7, spec["material"]["lc"], "test")
    verified = {**quick_config["ifenn"]["verification"], "enabled": True}
    run_spec = {**spec, **{k: quick_config["ifenn"][k] for k in IFENN_OPTIONS}, "name": "verified", "smoothing_sigma": None,
                "irreversible": False, "pixel_padding": "replicate", "inference": "process_zone",
                "process_zone": quick_config["ifenn"]["process_zone"], "verification": verified}
    hybrid = pd.DataFrame(run_ifenn(run_spec, tmp_path / "mesh.xdmf", tmp_path / "fem", model, tmp_path / "verified", progress=False))
    active = hybrid[hybrid.hybrid_active == 1]
    assert len(active) > 0 and (active.verify_residual_after <= verified["tolerance"]).all()
    peak = fem.reaction_force.max()
    assert np.abs(hybrid.reaction_force.to_numpy() - fem.reaction_force.to_numpy()).max() < 0.05 * peak
    service = read_provenance(tmp_path / "verified")["network_material"]
    assert service["history_scale"] == pytest.approx(2.0) and service["fallback"] is None


@pytest.mark.parametrize("elements, lc, message", [
    ([4, 4], 0.3, "the mesh resolves the phase field from lc/h = 2"),      # lc/h = 1.2
    ([16, 16], 1.5, "not smaller than scene 'panel'"),
])
def test_an_lc_the_mesh_cannot_resolve_or_larger_than_the_specimen_is_refused(with_panel, elements, lc, message):
    with_panel["scenes"]["panel"]["elements"] = elements
    with_panel["scenes"]["panel"]["material"]["lc"] = lc
    with pytest.raises(ConfigError, match=message) as info:
        validate_config(with_panel, petsc_names=False)
    assert "config key 'scenes.panel.material.lc'" in str(info.value)
