"""IFENN over the whole load path and the switch-over criterion: on the quick scene,
verified IFENN from the first increment reaches FEM's peak within a stated tolerance, and every
IFENN run's provenance says which criterion fired and at which increment."""

import copy
import json

import numpy as np
import pandas as pd
import pytest
from conftest import quick_fem_run

from ifenn.config import IFENN_OPTIONS, fem_run_spec, ifenn_run_spec
from ifenn.fem.mesh import build_mesh, write_mesh
from ifenn.fem.solver import run_fem
from ifenn.hybrid.runs import run_ifenn
from ifenn.pixels import PixelGrid
from ifenn.studies.drivers.whole_path import whole_path_comparison

#: whole-path verified IFENN against FEM on the quick snt1-II: peak force (measured 0.04 % with the
#: quick network, 0.04 % with an untrained one: the check certifies the same pixel solution), u at
#: the peak (the same increment), post-peak RMS (measured 0.55 %)
PEAK_TOLERANCE, U_PEAK_TOLERANCE, POST_PEAK_RMS_TOLERANCE = 0.005, 0.02, 0.02


@pytest.fixture(scope="module")
def fem_run(quick_config, tmp_path_factory):
    return quick_fem_run(quick_config, tmp_path_factory, "snt1-II", "whole")


def _random_model(spec, path):
    """An untrained PICNN: the verified step has to correct all of its prediction."""
    import torch

    from ifenn.network.picnn import PICNN, InputScaling, save_picnn

    torch.manual_seed(0)
    net = PICNN(padding="replicate", input_scaling=InputScaling("log", 0.01, 45.0), init_gain=2.0).eval()
    save_picnn(net, path, PixelGrid.for_scene(spec["scene"]).h_px, spec["material"]["Gc"], spec["material"]["lc"], "test")
    return path


def _provenance(folder):
    return json.loads((folder / "provenance.json").read_text())["switch_over"]


def test_whole_path_verified_ifenn_reaches_fem_peak(fem_run, quick_config, tmp_path):
    """snt1-II-whole of the quick config (the verified step from the first increment, no FEM
    state read: fem_dir None): peak within PEAK_TOLERANCE of FEM's, u at the peak within
    U_PEAK_TOLERANCE, post-peak force RMS within POST_PEAK_RMS_TOLERANCE of FEM's peak, every
    increment certified; provenance: criterion 'start', no FEM increment."""
    _, tmp, fem = fem_run
    spec = ifenn_run_spec(quick_config, "snt1-II-whole")
    model = _random_model(spec, tmp_path / "random.pt")
    whole = pd.DataFrame(run_ifenn(spec, tmp / "mesh.xdmf", None, model, tmp_path / "whole", progress=False, device="cpu"))
    assert json.loads((tmp_path / "whole" / "provenance.json").read_text())["network_device"] == "cpu"
    assert len(whole) == len(fem) and (whole.hybrid_active == 1).all()
    # the network predicts from the first increment on, and again wherever the input moved by the
    # verification's network_tolerance (not every increment: elsewhere the last verified phi stays)
    assert whole.t_inference_s.iloc[0] > 0 and (whole.evaluated_fraction > 0).sum() >= 5
    np.testing.assert_allclose(whole.u, fem.u)
    assert (whole.verify_residual_after <= spec["verification"]["tolerance"]).all()
    row = whole_path_comparison(fem, whole, spec["switch_phi_max"])
    assert abs(row["peak_force_rel_error"]) <= PEAK_TOLERANCE, row
    assert abs(row["u_peak_rel_error"]) <= U_PEAK_TOLERANCE, row
    assert row["post_peak_rms_error"] <= POST_PEAK_RMS_TOLERANCE, row
    assert row["pre_nucleation_increments"] > 0 and row["pre_nucleation_verify_corrected_fraction_mean"] > 0
    record = _provenance(tmp_path / "whole")
    assert record["criterion"] == "start" and record["fem_increments"] == 0 and record["first_ifenn_increment"] == 1


def test_paired_whole_run_equals_the_runs_alone(fem_run, quick_config, tmp_path):
    """The whole-run benchmark's pair (FEM and whole-path IFENN in one process, increments
    interleaved) writes the same two runs as run alone: every history value but the times equal
    (the same solves in another order), both run directories complete, and its table's forces are
    the runs' own; each run's wall time counts only its own increments."""
    import torch

    from ifenn.studies.drivers.whole_run_benchmark import paired_whole_run, whole_run_speed

    spec, tmp, fem = fem_run
    whole_spec = ifenn_run_spec(quick_config, "snt1-II-whole")
    model = _random_model(whole_spec, tmp_path / "random.pt")
    alone = pd.DataFrame(run_ifenn(whole_spec, tmp / "mesh.xdmf", None, model, tmp_path / "alone", progress=False, device="cpu"))
    summary, increments = paired_whole_run(spec, whole_spec, tmp / "mesh.xdmf", model, tmp_path / "fem", tmp_path / "whole",
                                           device="cpu", devices=[], progress=False)
    for reference, folder in ((fem, "fem"), (alone, "whole")):
        paired = pd.read_csv(tmp_path / folder / "history.csv")
        physics = [c for c in paired.columns if not c.startswith("t_")]
        pd.testing.assert_frame_equal(paired[physics], reference[physics], check_exact=False, rtol=1e-9, atol=1e-12)
        assert {p.name for p in (tmp_path / folder).iterdir()} >= {"history.csv", "fields.h5", "paraview.xdmf", "paraview.h5",
                                                                   "provenance.json"}
        assert not (tmp_path / folder / ".work").exists()
        wall = json.loads((tmp_path / folder / "provenance.json").read_text())["wall_time_s"]
        assert paired.t_increment_s.sum() <= wall < summary.t_increment_total_s.sum()
    rows = summary.set_index("method")
    assert list(rows.increments) == [len(fem)] * 2 and rows.loc["fem", "final_force"] == pytest.approx(fem.reaction_force.iloc[-1])
    assert rows.loc["ifenn", "peak_force"] == pytest.approx(alone.reaction_force.abs().max())
    assert len(increments) == 2 * len(fem) and rows.loc["ifenn", "phase_field_speedup_vs_fem"] > 0
    # the standalone benchmark (benchmarks/whole_run_speed.py) interleaves the same runs, on their first increments
    first = 6
    _, standalone = whole_run_speed([whole_spec], {whole_spec["name"]: {"mesh": tmp / "mesh.xdmf"}}, model, increments=first,
                                    progress=False, devices=[torch.device("cpu")])
    for method, reference in (("fem", fem), ("ifenn", alone)):
        rows = standalone[standalone.method == method]
        assert list(rows.increment) == list(range(1, first + 1))
        np.testing.assert_allclose(rows.reaction_force, reference.reaction_force.iloc[:first], rtol=1e-9, atol=1e-12)


def _exact_spec(fem_spec, quick_config, name, **options):
    spec = copy.deepcopy(fem_spec)
    spec.update({k: quick_config["ifenn"][k] for k in IFENN_OPTIONS}, name=name, fem_run="snt1-II", predictor="exact_pixel",
                smoothing_sigma=None, pixel_padding="replicate", **options)
    return spec


def test_switch_at_a_given_increment_and_at_the_phi_threshold(fem_run, quick_config, tmp_path):
    """switch_over 'increment' continues the FEM state saved there (rows 1..k copied); the paper's
    threshold continues FEM's first increment with phi_max > switch_phi_max; an increment the FEM run
    did not save is refused, naming what it saved. Both say so in provenance.json."""
    fem_spec, tmp, fem = fem_run
    spec = _exact_spec(fem_spec, quick_config, "at-10", switch_over="increment", switch_increment=10)
    at_10 = pd.DataFrame(run_ifenn(spec, tmp / "mesh.xdmf", tmp / "fem", None, tmp_path / "at-10", progress=False))
    assert list(at_10.hybrid_active) == [0] * 10 + [1] * (len(fem) - 10)
    pd.testing.assert_frame_equal(at_10.iloc[:10][fem.columns], fem.iloc[:10], check_dtype=False)
    record = _provenance(tmp_path / "at-10")
    assert record["criterion"] == "increment" and record["fem_increments"] == 10 and record["first_ifenn_increment"] == 11
    assert record["u_switch"] == pytest.approx(fem.u.iloc[9])
    threshold = pd.DataFrame(run_ifenn(_exact_spec(fem_spec, quick_config, "threshold"), tmp / "mesh.xdmf", tmp / "fem", None,
                                       tmp_path / "threshold", progress=False))
    switch = int(fem.increment[fem.phi_max > fem_spec["switch_phi_max"]].iloc[0])
    record = _provenance(tmp_path / "threshold")
    assert record == {**record, "criterion": "phi_threshold", "fem_increments": switch, "switch_phi_max": fem_spec["switch_phi_max"],
                      "fired_at_first_increment": False}
    assert record["phi_max_at_switch"] > fem_spec["switch_phi_max"] and int((threshold.hybrid_active == 0).sum()) == switch
    with pytest.raises(KeyError, match="did not save increment 12"):
        run_ifenn(_exact_spec(fem_spec, quick_config, "at-12", switch_over="increment", switch_increment=12),
                  tmp / "mesh.xdmf", tmp / "fem", None, tmp_path / "at-12", progress=False)


def test_history_notch_fires_the_threshold_at_the_first_increment(quick_config, tmp_path):
    """A history notch (Borden's initial H) holds phi near 1 at the notch from the first
    increment: the paper's threshold switches at FEM increment 1, and the provenance says so."""
    spec = copy.deepcopy(fem_run_spec(quick_config, "snt1-II"))
    spec["scene"]["notches"] = [{"kind": "history", "start": [-0.5, 0.0], "end": [-0.2, 0.0]}]
    spec.update(load=spec["load"][:4], save_fields=[2, 4])
    write_mesh(build_mesh(spec["scene"]), tmp_path / "mesh.xdmf")
    fem = pd.DataFrame(run_fem(spec, tmp_path / "mesh.xdmf", tmp_path / "fem", progress=False))
    assert fem.phi_max.iloc[0] > spec["switch_phi_max"]
    hybrid = pd.DataFrame(run_ifenn(_exact_spec(spec, quick_config, "notch"), tmp_path / "mesh.xdmf", tmp_path / "fem", None,
                                    tmp_path / "notch", progress=False))
    assert list(hybrid.hybrid_active) == [0, 1, 1, 1]
    record = _provenance(tmp_path / "notch")
    assert record["criterion"] == "phi_threshold" and record["fem_increments"] == 1 and record["fired_at_first_increment"]
    assert "history notch" in record["note"]


def test_the_verified_step_asks_the_network_on_its_own_tolerance(quick_config, tmp_path):
    """verification.network_tolerance sets how far an input moves before the network predicts it
    again (null: the process zone's tolerance); with warm_start 'previous' there is no network."""
    from ifenn.hybrid.runs import make_inference

    spec = ifenn_run_spec(quick_config, "snt1-II-verified")
    model = _random_model(spec, tmp_path / "random.pt")
    h_px = PixelGrid.for_scene(spec["scene"]).h_px
    verified = make_inference(spec, model, h_px)
    assert verified.warm_start == spec["verification"]["warm_start"] == "increment"
    assert verified.inference.tolerance == spec["verification"]["network_tolerance"] != spec["process_zone"]["tolerance"]
    inherit = copy.deepcopy(spec)
    inherit["verification"]["network_tolerance"] = None
    assert make_inference(inherit, model, h_px).inference.tolerance == spec["process_zone"]["tolerance"]
    alone = copy.deepcopy(spec)
    alone["verification"]["warm_start"] = "previous"
    assert make_inference(alone, model, h_px).inference is None
