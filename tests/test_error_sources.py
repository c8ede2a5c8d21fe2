"""The error split of IFENN replayed on FEM states (ifenn.studies.drivers.error_sources), on the quick snt1 scene:
the exact variant solves the pixel equation, switching a source off makes its contribution
vanish, and the parts add up to the published step's error."""

import copy
import json

import numpy as np
import pandas as pd
import pytest
import torch

from ifenn.config import fem_run_spec, ifenn_run_spec
from ifenn.fem.mesh import build_mesh, write_mesh
from ifenn.fem.solver import run_fem
from ifenn.network.picnn import PICNN, save_picnn
from ifenn.pixel_equation.torch_backend import residual
from ifenn.studies.drivers.error_sources import (
    PUBLISHED_PARTS,
    Replay,
    crack_band_min,
    error_sources,
    postswitch_error,
    saved_states,
)


@pytest.fixture(scope="module")
def case(quick_config, tmp_path_factory):
    """A quick snt1-I FEM run, the IFENN spec, an (untrained, seeded) PICNN and a stand-in for the
    published IFENN history (FEM's own rows, marked hybrid after the switch: zero post-switch error)."""
    tmp = tmp_path_factory.mktemp("error_sources")
    spec = fem_run_spec(quick_config, "snt1-I")
    write_mesh(build_mesh(spec["scene"]), tmp / "mesh.xdmf")
    fem = pd.DataFrame(run_fem(spec, tmp / "mesh.xdmf", tmp / "fem", progress=False))
    ifenn_spec = ifenn_run_spec(quick_config, "snt1-I")
    (tmp / "spec.json").write_text(json.dumps(ifenn_spec))
    torch.manual_seed(0)
    model = PICNN(history_cap=ifenn_spec["history_cap"], padding="replicate")
    material = ifenn_spec["material"]
    h_px = (spec["scene"]["domain"]["x"][1] - spec["scene"]["domain"]["x"][0]) / spec["scene"]["elements"][0] / 2
    save_picnn(model, tmp / "model.pt", h_px, material["Gc"], material["lc"], "test")
    switch = int(fem.increment[fem.phi_max > ifenn_spec["switch_phi_max"]].iloc[0])
    fem.assign(hybrid_active=(fem.increment > switch).astype(int)).to_csv(tmp / "ifenn_history.csv", index=False)
    return {"spec": tmp / "spec.json", "mesh": tmp / "mesh.xdmf", "fem_dir": tmp / "fem",
            "ifenn_history": tmp / "ifenn_history.csv", "model": tmp / "model.pt"}, ifenn_spec, tmp


def _with(case, tmp, name, **options):
    paths, spec, _ = case
    spec = {**copy.deepcopy(spec), "name": name, **options}
    path = tmp / f"{name}.json"
    path.write_text(json.dumps(spec))
    return {**paths, "spec": path}


def test_fem_run_saved_states_after_the_switch(case):
    paths, _, _ = case
    switch, attrs, states = saved_states(paths["fem_dir"] / "fields.h5")
    assert switch > 0 and len(states) >= 2
    assert all(s["increment"] > switch for s in states)
    assert states[0]["history"].shape == (attrs["ny_px"], attrs["nx_px"]) == states[0]["phase_field_gp"].shape


def test_exact_variant_solves_the_pixel_equation(case):
    """The exact variant's phi makes the pixel residual (the slit's links cut) vanish on the
    capped H (to the CG tolerance), and the uncapped one on the uncapped H; both lie in [0, 1]."""
    from ifenn.hybrid.runs import slit_cuts

    paths, spec, _ = case
    replay = Replay(spec, paths["mesh"], paths["model"], stagger_max_iterations=5)
    _, _, states = saved_states(paths["fem_dir"] / "fields.h5")
    material = spec["material"]
    for history in (replay.capped(states[-1]["history"]), states[-1]["history"]):
        phi = replay.exact(history)
        as_tensor = (lambda a: torch.as_tensor(a, dtype=torch.float64)[None, None])  # noqa: E731
        r = residual(as_tensor(phi), as_tensor(history), material["Gc"], material["lc"], replay.h_px, spec["pixel_padding"],
                     slit_cuts(spec))
        assert float(r.norm() / torch.as_tensor(2.0 * history).norm()) < 1e-8
        assert phi.min() >= 0.0 and phi.max() <= 1.0


def test_sources_add_up_and_vanish_when_switched_off(case):
    """The five parts' signed means add up to the published step's; with the smoothing off the
    smoothing contribution is zero; with the cap above every H the cap contribution is zero; the
    stand-in IFENN history (= FEM) has zero post-switch error."""
    paths, spec, tmp = case
    top = float(max(s["history"].max() for s in saved_states(paths["fem_dir"] / "fields.h5")[2]))
    cases = [_with(case, tmp, "plain"), _with(case, tmp, "no-smoothing", smoothing_sigma=None),
             _with(case, tmp, "no-cap", history_cap=10.0 * top)]
    sources, states = error_sources(cases, stagger_max_iterations=20)
    assert len(sources) == 3 * 7 and list(dict.fromkeys(sources.run)) == ["plain", "no-smoothing", "no-cap"]
    for k in range(3):
        rows = sources.iloc[7 * k: 7 * (k + 1)].set_index("source")
        assert rows.loc[list(PUBLISHED_PARTS), "force_mean"].sum() == pytest.approx(rows.loc["published_step", "force_mean"], abs=1e-12)
        assert rows.postswitch_rms_error.iloc[0] == pytest.approx(0.0, abs=1e-12)
        assert rows.final_force_ifenn.iloc[0] == pytest.approx(rows.final_force_fem.iloc[0])
        assert (rows.states == rows.states.iloc[0]).all() and rows.states.iloc[0] >= 2
    smooth, no_smoothing, no_cap = (sources.iloc[7 * k: 7 * (k + 1)].set_index("source") for k in range(3))
    assert no_smoothing.loc["smoothing", "force_rms"] == 0.0 and no_smoothing.loc["smoothing", "phi_max_abs"] == 0.0
    assert smooth.loc["smoothing", "phi_max_abs"] > 1e-3   # the published smoothing does change phi
    assert no_cap.loc["cap", "force_rms"] == 0.0 and no_cap.loc["cap", "phi_max_abs"] == 0.0
    # per state too: the fem variant is the reference of every force difference
    fem_rows = states[states.variant == "fem"]
    assert (fem_rows.force_vs_fem == 0).all() and (fem_rows.phi_max_abs_error == 0).all()
    converged = states[states.variant == "fem_converged"]
    assert (converged.stagger_passes >= 1).all() and (converged.stagger_passes <= 20).all()


def test_converged_staggering_satisfies_the_fem_equations(case):
    """The converged variant is a fixed point of the staggered pass: one more pass from it moves
    phi by less than the stagger tolerance."""
    paths, spec, _ = case
    replay = Replay(spec, paths["mesh"], paths["model"], stagger_max_iterations=200)
    _, _, states = saved_states(paths["fem_dir"] / "fields.h5")
    one_more, converged, passes = replay.staggered(states[-1])
    assert 1 <= passes < 200 and one_more.shape == converged.shape
    p = replay.problem
    before = p.phase_field_gp.x.array.copy()
    p.solve_displacement(states[-1]["u"])
    p.update_history()
    replay.fem_step.solve()
    assert np.abs(p.phase_field_gp.x.array - before).max() < spec["stagger_tolerance"]


def test_crack_band_min_and_postswitch_error():
    phi = np.zeros((20, 20))
    phi[10, :] = 1.0
    phi[10, 5] = 0.6        # the weakest point of the crack line
    phi[9, 5] = 0.7         # but the band's largest phi there is 0.7 (one pixel off the line)
    crack = np.zeros_like(phi, dtype=bool)
    crack[10, 2:18] = True
    assert crack_band_min(phi, crack, 1) == pytest.approx(1.0)   # neighbours on the line at 1
    phi[10, 4:7] = 0.6
    assert crack_band_min(phi, crack, 1) == pytest.approx(0.7)
    assert np.isnan(crack_band_min(phi, np.zeros_like(crack), 1))
    fem = pd.DataFrame({"u": [0.0, 1.0, 2.0, 3.0], "reaction_force": [0.0, 10.0, 5.0, 0.0]})
    ifenn = fem.assign(reaction_force=[0.0, 10.0, 6.0, 2.0], hybrid_active=[0, 0, 1, 1])
    figures = postswitch_error(ifenn, fem)
    assert figures["postswitch_increments"] == 2 and figures["u_switch"] == 2.0
    assert figures["postswitch_rms_error"] == pytest.approx(np.sqrt((1.0 + 4.0) / 2) / 10.0)
    assert figures["postswitch_max_error"] == pytest.approx(0.2)
    assert figures["final_force_ifenn"] == pytest.approx(0.2) and figures["final_force_fem"] == 0.0


def test_without_network_or_ifenn_run_the_other_sources_remain(case):
    """No model and no IFENN history (e.g. before training): pixel, cap and staggering are still
    split off; the whole-run columns are nan."""
    paths, _, _ = case
    sources, states = error_sources([{**paths, "model": None, "ifenn_history": None}], stagger_max_iterations=5)
    assert list(sources.source) == ["pixel", "cap", "staggering"]
    assert set(states.variant) == {"fem", "exact_uncapped", "exact", "fem_one_more_pass", "fem_converged"}
    assert sources.postswitch_rms_error.isna().all() and (sources.final_force_fem >= 0).all()
