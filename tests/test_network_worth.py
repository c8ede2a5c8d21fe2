"""What a network is worth to the verified step (ifenn.studies.drivers.network_worth), on the quick snt1-I
scene: every warm start replayed on the loop's own history images ends with the same certificate,
and the oracle that knows the exact solution leaves the correction nothing to do."""

import numpy as np
import pytest
import torch
from conftest import quick_fem_run

from ifenn.config import ifenn_run_spec
from ifenn.network.picnn import PICNN, InputScaling, save_picnn
from ifenn.studies.drivers.network_worth import VARIANTS, network_worth


@pytest.fixture(scope="module")
def worth(quick_config, tmp_path_factory):
    spec, tmp, _ = quick_fem_run(quick_config, tmp_path_factory, "snt1-I", "worth")
    run = ifenn_run_spec(quick_config, "snt1-I-verified")
    torch.manual_seed(0)
    net = PICNN(padding="replicate", input_scaling=InputScaling("log", 0.01, 45.0), init_gain=2.0).eval()
    model = tmp / "random.pt"   # an untrained network: the check must hold whatever it answers
    save_picnn(net, model, spec["scene"]["domain"]["x"][1] / spec["scene"]["elements"][0], 2.7, quick_config["material"]["lc"], "test")
    summary, rows = network_worth([run], {run["name"]: {"mesh": tmp / "mesh.xdmf", "fem_dir": tmp / "fem"}}, model, increments=6)
    return run, summary, rows


def test_every_warm_start_ends_with_the_same_certificate(worth):
    run, summary, rows = worth
    tolerance = run["verification"]["tolerance"]
    assert list(summary.variant) == list(VARIANTS)
    assert (rows.residual_after <= tolerance).all()
    assert (summary.increments == 5).all() and (summary.t_step_s > 0).all()
    no_network = summary.set_index("variant").loc["no network"]
    assert no_network.cg_iterations > 0 and no_network.speedup_vs_no_network == pytest.approx(1.0)


def test_the_oracle_leaves_nothing_to_correct(worth):
    """The exact pixel solution as the warm start: the check passes at once (the oracles' answers
    cost nothing; the paper's network is asked and timed)."""
    _, summary, rows = worth
    oracle = rows[rows.variant == "oracle everywhere"]
    assert (oracle.cg_iterations == 0).all() and (oracle.residual_before <= 1e-8).all()
    by = summary.set_index("variant")
    assert by.loc["oracle everywhere", "t_network_s"] == 0 and by.loc["paper's network", "t_network_s"] > 0


def test_the_figure_shows_every_run(worth, tmp_path):
    from ifenn.studies.figures import network_worth_figure

    _, summary, _ = worth
    network_worth_figure(summary, tmp_path / "worth.png")
    assert (tmp_path / "worth.png").stat().st_size > 10_000


def test_the_change_network_trains_deterministically_and_is_certified_on_states_it_never_saw():
    """Trained on two increments of one crack, fed another crack's increments: whatever it answers,
    the check and correction end within the tolerance of the exact pixel solution; the same seed gives
    the same weights."""
    from ifenn.hybrid.verification import VerifiedInference
    from ifenn.network.change_net import ChangeNetWarmStart, train_change_net
    from ifenn.network.training import synthetic_history
    from ifenn.pixel_equation.numpy_backend import PixelEquation, solve_pixel_equation

    Gc, lc, h_px = 2.7, 0.03, 0.0025
    seen = [synthetic_history(n_px=64, x_tip=x) for x in (-0.04, -0.03, -0.02)]
    states = [(h, solve_pixel_equation(h_old, Gc, lc, h_px, "replicate")) for h_old, h in zip(seen[:-1], seen[1:], strict=True)]
    settings = {"channels": (2, 4, 1), "epochs": 20, "crop": 32, "crops_per_state": 2}
    a, log = train_change_net(states, h_px, Gc, lc, seed=3, **settings)
    b, _ = train_change_net(states, h_px, Gc, lc, seed=3, **settings)
    for p, q in zip(a.parameters(), b.parameters(), strict=True):
        assert torch.equal(p, q)
    assert log["loss"][-1] < log["loss"][0]   # it learns the job on its own data
    network = ChangeNetWarmStart(a, Gc, lc, h_px)
    step = VerifiedInference(network, PixelEquation(Gc, lc, h_px), 1e-3, warm_start="increment")
    network.verified = step
    previous = None
    for x_tip in (0.0, 0.01, 0.02):   # another crack, further on
        history = synthetic_history(n_px=64, x_tip=x_tip, band_peak=1.0e5)
        history = history if previous is None else np.maximum(history, previous)
        previous = history
        out = step(history)
        exact = solve_pixel_equation(history, Gc, lc, h_px, "replicate", rtol=1e-12)
        assert step.residual_after <= 1e-3 and np.max(np.abs(out - exact)) <= 1e-3
