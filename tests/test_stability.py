"""Stability sweep: the cells the config defines, and the classifier on hand-made runs."""

import json

import numpy as np
import pandas as pd
import pytest

from ifenn.errors import NonFiniteResultError, SolverDivergedError
from ifenn.run_files import FIELDS, write_fields
from ifenn.studies.drivers.stability import cell_metrics, cells, classify, table_rows

THRESHOLDS = {"iou_min": 0.5, "final_force_max": 0.5, "peak_error_max": 0.05}


def _cell(path, force, crack="horizontal", status="ok", shape=(40, 40)):
    """A run folder: status.json, history.csv with the force curve, fields.h5 with a final
    phase field holding one straight crack."""
    path.mkdir(parents=True)
    (path / "status.json").write_text(json.dumps({"status": status, **({"error": "KSP diverged"} if status != "ok" else {})}))
    if status != "ok":
        return path
    u = np.linspace(1e-4, 1e-2, len(force))
    pd.DataFrame({"increment": np.arange(1, len(force) + 1), "u": u, "reaction_force": force}).to_csv(path / "history.csv", index=False)
    phi = np.zeros(shape)
    band = slice(shape[0] // 2 - shape[0] // 20, shape[0] // 2 + shape[0] // 20)  # a crack band 1/10 of the side wide
    if crack == "horizontal":
        phi[band, :] = 1.0
    else:
        phi[:, band] = 1.0
    n = shape[0] * shape[1] // 4  # nodes of the element mesh under the pixel grid (unused here)
    state = {"increment": len(force), "u": u[-1], "history": np.zeros(shape), "phase_field_gp": phi,
             "phase_field": np.zeros(n), "displacement": np.zeros((n, 2))}
    write_fields(path / FIELDS, {"switch_increment": -1}, [state])
    return path


@pytest.fixture
def reference(tmp_path):
    return _cell(tmp_path / "reference", [0, 50, 100, 80, 10, 1])


@pytest.mark.parametrize("force, crack, status, label", [
    ([0, 50, 100, 80, 10, 1], "horizontal", "ok", "ok"),
    ([0, 50, 100, 80, 10, 1], "horizontal", "diverged", "diverged"),
    ([0, 50, 100, 95, 90, 80], "horizontal", "ok", "no load drop"),
    ([0, 50, 100, 80, 10, 1], "vertical", "ok", "crack path wrong"),
    ([0, 55, 110, 80, 10, 1], "horizontal", "ok", "peak off"),
    ([0, 50, 104, 80, 10, 1], "horizontal", "ok", "ok"),          # 4 % off: within the 5 % allowed
    ([0, 55, 110, 95, 90, 80], "vertical", "ok", "no load drop"),  # the first label that applies
])
def test_classifier_labels_hand_made_runs(tmp_path, reference, force, crack, status, label):
    cell = _cell(tmp_path / "cell", force, crack, status)
    assert classify(cell_metrics(cell, reference), THRESHOLDS) == label


def test_crack_iou_compares_runs_on_different_pixel_grids(tmp_path, reference):
    """lc/h cells are compared with the finest mesh: phase fields are resampled to the coarser grid."""
    cell = _cell(tmp_path / "fine", [0, 50, 100, 80, 10, 1], shape=(80, 80))
    metrics = cell_metrics(cell, reference)
    assert metrics["crack_iou"] > 0.99 and classify(metrics, THRESHOLDS) == "ok"


def test_sweep_cells_of_the_paper_config(paper_config):
    all_cells = cells(paper_config)
    sweep = paper_config["stability"]
    fem = [c for c in all_cells.values() if c["method"] == "fem"]
    ifenn = [c for c in all_cells.values() if c["method"] == "ifenn"]
    assert len(fem) == len(sweep["steps"]) + len(sweep["lc_over_h"]) - 1
    assert len(ifenn) == len(fem) + len(sweep["ifenn_variants"])
    assert all(c["fem_cell"] in all_cells for c in ifenn)
    for c in all_cells.values():  # lc is the paper's; h follows lc/h; the schedule reaches u_end
        h = (c["spec"]["scene"]["domain"]["x"][1] - c["spec"]["scene"]["domain"]["x"][0]) / c["spec"]["scene"]["elements"][0]
        assert c["spec"]["material"]["lc"] / h == pytest.approx(c["lc_over_h"], rel=0.02)
        assert c["spec"]["load"][-1] == pytest.approx(sweep["u_end"])
    rows = table_rows(paper_config)
    assert {r["panel"] for r in rows} == {"load step", "lc/h", "IFENN option"}
    assert all(r["cell"] in all_cells and r["reference"] in all_cells for r in rows)


@pytest.mark.parametrize("error, labelled", [
    (SolverDivergedError("phase-field solve diverged: KSP_DIVERGED_ITS"), True),
    (NonFiniteResultError("non-finite result"), True),
    (RuntimeError("CUDA out of memory. Tried to allocate 2.00 GiB"), False),
    (ValueError("config key 'x': bad"), False),
])
def test_only_the_solvers_own_failure_is_labelled_diverged(quick_config, tmp_path, monkeypatch, error, labelled):
    """A cell says 'diverged' for the solver's own exception only; a foreign RuntimeError (a CUDA
    out-of-memory) or any other error fails the job with its message instead of a label."""
    import ifenn.fem.solver
    from ifenn.studies.drivers.stability import run_cell

    def failing(*args, **kwargs):
        raise error

    monkeypatch.setattr(ifenn.fem.solver, "run_fem", failing)
    spec = next(c["spec"] for c in cells(quick_config).values() if c["method"] == "fem")
    if labelled:
        status = run_cell(spec, tmp_path / "cell")
        assert status["status"] == "diverged" and str(error) in status["error"]
        assert json.loads((tmp_path / "cell" / "status.json").read_text())["status"] == "diverged"
    else:
        with pytest.raises(type(error), match=str(error).split(".")[0]):
            run_cell(spec, tmp_path / "cell")
        assert not (tmp_path / "cell" / "status.json").exists()


def test_the_sweep_keeps_a_scene_own_lc(paper_config):
    """A swept scene with its own material: the cells take its lc (not the config's) both for the
    scene's lc/h and for the elements each lc/h asks for."""
    import copy

    config = copy.deepcopy(paper_config)
    scene = config["scenes"][config["stability"]["scene"]]
    own_lc = 2.0 * config["material"]["lc"]
    scene["material"] = {"lc": own_lc}
    width = scene["domain"]["x"][1] - scene["domain"]["x"][0]
    base = own_lc / (width / scene["elements"][0])
    all_cells = cells(config)
    assert any(c["lc_over_h"] == pytest.approx(base) for c in all_cells.values())
    for c in all_cells.values():
        spec = c["spec"]
        h = width / spec["scene"]["elements"][0]
        assert spec["material"]["lc"] == own_lc
        assert own_lc / h == pytest.approx(c["lc_over_h"], rel=0.02)
