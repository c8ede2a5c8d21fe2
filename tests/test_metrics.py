"""Accuracy metrics: the crack energy of the analytic AT2 profile, IoU, timing ratios."""

import numpy as np
import pandas as pd
import pytest

from ifenn.studies.tables.metrics import crack_iou, dissipated_energy, force_curve_error, post_peak_rms, timing


@pytest.mark.parametrize("lc_over_h_px", [6, 12])
def test_straight_at2_crack_dissipates_gc_per_unit_length(lc_over_h_px):
    """phi = exp(-|y|/lc) across a crack of length L: int Gc/(2lc)(phi^2 + lc^2 phi'^2) = Gc L.
    The crack line runs through pixel centres (an odd number of rows), so phi = 1 is sampled;
    the sums are then geometric series that differ from Gc L by O((h/lc)^2)."""
    Gc, lc = 2.7, 0.03
    h_px = lc / lc_over_h_px
    width = 0.6
    rows = 2 * int(0.3 / h_px) + 1
    y = (np.arange(rows) - rows // 2) * h_px
    phi = np.repeat(np.exp(-np.abs(y) / lc)[:, None], int(width / h_px), axis=1)
    assert dissipated_energy(phi, h_px, Gc, lc) == pytest.approx(Gc * width, rel=0.01)


def test_crack_iou():
    a = np.zeros((10, 10))
    b = np.zeros((10, 10))
    assert crack_iou(a, b) == 1.0
    a[4, :6] = 1.0
    b[4, :3] = 1.0
    assert crack_iou(a, b) == pytest.approx(0.5)
    assert crack_iou(a, np.roll(a, 3, axis=0)) == 0.0


def test_timing_compares_the_same_increments():
    fem = pd.DataFrame({"increment": [1, 2, 3, 4], "t_displacement_s": 1.0, "t_phase_field_s": [9, 9, 1, 1.0],
                        "t_history_s": 0.1, "t_increment_s": [10, 10, 2.1, 2.1]})
    ifenn = fem.assign(t_phase_field_s=[9, 9, 3, 3.0], t_increment_s=[10, 10, 4.1, 4.1], t_inference_s=[0, 0, 2.5, 2.5],
                       hybrid_active=[0, 0, 1, 1])
    rows = {r["method"]: r for r in timing(fem, ifenn)}
    assert rows["fem"]["increments"] == rows["ifenn"]["increments"] == 2
    assert rows["ifenn"]["phase_field_time_vs_fem"] == pytest.approx(3.0)
    assert rows["fem"]["phase_field_cumulative_s"] == pytest.approx(2.0)


def test_force_curve_error_compares_at_equal_displacement():
    """The same curve sampled with other load steps has no error; 1 % more force everywhere
    is a 1 % error; a drop taken 5 % of the range later is a large one."""
    def curve(u):
        return np.where(u < 0.6, 1000 * u, np.maximum(600 - 4000 * (u - 0.6), 0.0))

    fine = np.linspace(0, 1, 2001)
    coarse = np.concatenate([np.linspace(0, 0.6, 7), np.linspace(0.6005, 1, 801)])
    assert force_curve_error(coarse, curve(coarse), fine, curve(fine)) < 1e-3
    assert force_curve_error(fine, 1.01 * curve(fine), fine, curve(fine)) == pytest.approx(0.01, rel=1e-6)
    assert force_curve_error(fine, curve(fine - 0.05), fine, curve(fine)) > 0.1


def test_crack_ridge_phi_is_the_weakest_section_of_the_band():
    """A straight band from a notch tip to the right edge with phi = 0.999 on its centre line
    but 0.9 in one column: the weakest section is 0.9; a band that stops short connects nothing
    beyond the far field's phi."""
    from ifenn.studies.tables.metrics import crack_ridge_phi

    ny, nx = 60, 80
    rows = np.arange(ny)[:, None]
    band = np.exp(-np.abs(rows - 30) / 3.0) * np.ones((1, nx))
    phi = 0.999 * band
    phi[:, :20] = 0.0           # the notch region left of the tip (column 20)
    phi[:, 50] *= 0.9 / 0.999   # the weak section
    tips = [((30, 20), (30, 0))]
    assert crack_ridge_phi(phi, tips) == pytest.approx(0.9, abs=1e-6)
    short = phi.copy()
    short[:, 60:] = 0.05
    assert crack_ridge_phi(short, tips) == pytest.approx(0.05, abs=1e-6)
    # two tips: the cracks from both meet where phi is lowest between them
    two = 0.999 * band
    two[30, 39:41] = 0.7
    two[29, 39:41] = two[31, 39:41] = 0.6
    assert crack_ridge_phi(two, [((30, 5), None), ((30, 75), None)]) == pytest.approx(0.7, abs=1e-6)


def test_post_switch_error_counts_only_hybrid_increments():
    from ifenn.studies.tables.metrics import post_switch_force_error

    u = np.linspace(0, 1, 11)
    fem = pd.DataFrame({"u": u, "reaction_force": 10 * np.minimum(u, 1 - u) * 2})
    ifenn = fem.assign(hybrid_active=(u > 0.5).astype(int))
    ifenn.loc[ifenn.u > 0.5, "reaction_force"] += 1.0
    ifenn.loc[1, "reaction_force"] += 5.0   # before the switch: not counted
    out = post_switch_force_error(fem, ifenn)
    assert out["post_switch_increments"] == 5
    assert out["post_switch_rms_error"] == pytest.approx(1.0 / 10.0)
    assert out["post_switch_max_error"] == pytest.approx(1.0 / 10.0)


def test_post_peak_rms_counts_only_after_the_reference_peak():
    """A curve equal to the reference before its peak and 2 N/mm above it after: the RMS is 2 /
    peak, whatever the run's own increments; a run that ends before the peak has none (NaN)."""
    u_ref = np.linspace(0.0, 1.0, 101)
    f_ref = 100.0 * np.minimum(u_ref / 0.4, np.maximum(0.0, (1.0 - u_ref) / 0.6))   # peak 100 at u = 0.4
    u = np.linspace(0.0, 1.0, 37)
    force = np.interp(u, u_ref, f_ref) + np.where(u > 0.4, 2.0, 0.0)
    assert abs(post_peak_rms(u, force, u_ref, f_ref) - 0.02) < 1e-12
    assert abs(post_peak_rms(u, -force, u_ref, f_ref) - 0.02) < 1e-12    # |F|: the sign of a reaction is a convention
    assert np.isnan(post_peak_rms(u[u < 0.3], force[u < 0.3], u_ref, f_ref))


def test_half_drop_and_work_of_the_load_on_a_known_curve():
    """A triangle rising to 1 at u = 1 and falling to 0 at u = 2: the force is half the peak again
    at u = 1.5, the work to the end is 1; a curve whose drop comes later has a later half drop and
    more work, one cut short at its peak has none (NaN)."""
    from ifenn.studies.tables.metrics import u_at_half_drop, work_of_load

    u = np.linspace(0.0, 2.0, 41)
    force = np.minimum(u, 2.0 - u)
    assert u_at_half_drop(u, force) == pytest.approx(1.5) and work_of_load(u, force, 2.0) == pytest.approx(1.0)
    later = np.minimum(u, 1.2 * (2.0 - u)).clip(0)
    assert u_at_half_drop(u, later) > 1.5 and work_of_load(u, later, 2.0) > 1.0
    assert np.isnan(u_at_half_drop(u[:21], force[:21]))
