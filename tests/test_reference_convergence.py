"""The reference-convergence table: IFENN and its FEM reference against a finer FEM after the peak."""

import copy

import numpy as np
import pandas as pd
import pytest

from ifenn.config import validate_config
from ifenn.studies.tables.reference_convergence import reference_convergence_rows


def _history(u, force):
    return pd.DataFrame({"increment": np.arange(1, len(u) + 1), "u": u, "reaction_force": force})


def _brittle(u, u_drop, peak=500.0, u_peak=6e-3):
    """Linear rise to the peak, then a drop of width 2e-4 centred at u_drop (a smooth brittle curve)."""
    rise = peak * u / u_peak
    return np.where(u <= u_peak, rise, peak / (1.0 + np.exp((u - u_drop) / 2e-5)))


def test_a_run_that_follows_the_finer_fem_is_closer_to_it_and_the_numbers_are_the_shift():
    u = np.linspace(1e-5, 7e-3, 700)
    fine = _history(u, _brittle(u, 6.30e-3))
    coarse = _history(u, _brittle(u, 6.34e-3))          # FEM at h drops 4e-5 later
    like_fine = _history(u[::2], _brittle(u[::2], 6.30e-3))  # a run on the finer answer, other increments
    like_coarse = _history(u, _brittle(u, 6.34e-3))
    rows = {r["run"]: r for r in reference_convergence_rows(coarse, fine, {"fine": like_fine, "coarse": like_coarse})}
    fem = rows[""]
    assert fem["method"] == "fem" and fem["rms_vs_fine"] > 0.05  # a 4e-5 shift of a 2e-4 wide drop
    assert rows["fine"]["rms_vs_fine"] < 1e-3 and rows["fine"]["closer_to_fine"]
    assert rows["fine"]["rms_vs_fem"] == pytest.approx(fem["rms_vs_fine"], rel=0.1)  # the same gap, seen from the other side
    assert rows["coarse"]["rms_vs_fem"] < 1e-12 and not rows["coarse"]["closer_to_fine"]
    assert rows["fine"]["u_half_drop"] == pytest.approx(6.30e-3, abs=2e-5)
    assert fem["u_half_drop_fem"] == pytest.approx(6.34e-3, abs=2e-5)


def test_a_finer_reference_that_ends_early_is_refused():
    u = np.linspace(1e-5, 7e-3, 700)
    with pytest.raises(ValueError, match="share the schedule"):
        reference_convergence_rows(_history(u, _brittle(u, 6.3e-3)), _history(u[:600], _brittle(u[:600], 6.3e-3)), {})


def test_config_refuses_a_finer_reference_that_is_not_the_same_specimen(paper_config):
    config = copy.deepcopy(paper_config)
    config["fem_runs"]["snt1-II-fine"]["schedule"] = "I"
    runs = config["reference_convergence"]["snt1-II"]["ifenn_runs"]
    runs.append("sdnt")
    with pytest.raises(ValueError) as error:
        validate_config(config)
    text = str(error.value)
    assert "reference_convergence.snt1-II.fine_fem_run" in text and "['schedule']" in text
    assert f"reference_convergence.snt1-II.ifenn_runs[{len(runs) - 1}]" in text and "continues FEM run 'sdnt'" in text


def test_config_refuses_a_finer_reference_of_another_specimen_in_adaptive_resolution(paper_config):
    """adaptive_resolution's finer reference is checked as reference_convergence's: another specimen
    (here sdnt's finer run for snt1-II) is refused, naming the key, before any job."""
    config = copy.deepcopy(paper_config)
    config["adaptive_resolution"]["snt1-II"]["fine_fem_run"] = "sdnt-fine"
    with pytest.raises(ValueError) as error:
        validate_config(config)
    text = str(error.value)
    assert "adaptive_resolution.snt1-II.fine_fem_run" in text and "'sdnt-fine' differs from 'snt1-II'" in text
