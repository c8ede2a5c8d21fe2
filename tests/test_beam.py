"""The three-point bending beam (config scene three-point-bending, quick size): mirror-symmetric
about mid-span, and its right half with a mirror plane (a roller on the cut edge) carries half the
whole beam's force."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest


def _run(config, tmp_path_factory, run):
    """The quick run with the direct solver (exact to round-off: the symmetry test's 1e-8 is below
    the iterative preset's CG tolerance)."""
    from ifenn.config import fem_run_spec
    from ifenn.fem.mesh import build_mesh, write_mesh
    from ifenn.fem.solver import run_fem

    folder = tmp_path_factory.mktemp(run)
    spec = {**fem_run_spec(config, run), "petsc": config["solver"]["linear_solver_presets"]["direct"], "linear_solvers": "direct"}
    write_mesh(build_mesh(spec["scene"]), folder / "mesh.xdmf")
    return spec, folder, pd.DataFrame(run_fem(spec, folder / "mesh.xdmf", folder / "fem", progress=False))


@pytest.fixture(scope="module")
def beams(quick_config, tmp_path_factory):
    return _run(quick_config, tmp_path_factory, "three-point-bending"), _run(quick_config, tmp_path_factory, "three-point-bending-half")


def test_the_beam_breaks(beams):
    (_, _, whole), _ = beams
    peak = whole.reaction_force.max()
    assert peak > 0 and whole.reaction_force.iloc[-1] < 0.2 * peak, "pushed down, the beam cracks through"
    assert whole.reaction_force.idxmax() < len(whole) - 5


def test_the_beam_stays_mirror_symmetric(beams):
    """phi(-x, y) = phi(x, y), u_x(-x, y) = -u_x(x, y), u_y(-x, y) = u_y(x, y) at every saved state
    while the beam still carries a tenth of its peak (slit twins included), to 1e-8 of the largest
    value. Once cut through, the halves hang on a band with g(phi) ~ 0: a near-mechanism whose
    antisymmetric mode round-off excites (1e-6 at 6 % of the peak, measured), as any solver's would."""
    from ifenn.fem.mesh import build_mesh
    from ifenn.run_files import read_states

    (spec, folder, history), _ = beams
    carrying = set(history.increment[history.reaction_force >= 0.1 * history.reaction_force.max()])
    points = build_mesh(spec["scene"]).points
    # the mirror image of each node: same y, opposite x; a slit twin (x = 0) mirrors onto its partner
    key = {(round(x, 9), round(y, 9)): [] for x, y in points}
    for i, (x, y) in enumerate(points):
        key[(round(x, 9), round(y, 9))].append(i)
    mirror = np.empty(len(points), dtype=np.int64)
    for i, (x, y) in enumerate(points):
        twins = key[(round(-x, 9), round(y, 9))]
        mirror[i] = twins[0] if len(twins) == 1 else [t for t in twins if t != i][0] if x == 0 and len(twins) == 2 else twins[0]
    states = [s for s in read_states(folder / "fem" / "fields.h5", keys=("phase_field", "displacement")) if s["increment"] in carrying]
    assert len(states) >= 4 and max(s["phase_field"].max() for s in states) > 0.9
    for state in states:
        phi, u = state["phase_field"], state["displacement"]
        np.testing.assert_allclose(phi[mirror], phi, atol=1e-8 * max(1.0, np.abs(phi).max()))
        scale = np.abs(u).max()
        np.testing.assert_allclose(u[mirror, 0], -u[:, 0], atol=1e-8 * scale)
        np.testing.assert_allclose(u[mirror, 1], u[:, 1], atol=1e-8 * scale)


def test_the_half_beam_doubled_is_the_whole_beam(beams):
    """The model no bigger than the scene needs: the half's force, doubled, is the whole's to 0.5 %
    of the peak at every increment while it carries load (the same mesh, mirrored)."""
    (_, _, whole), (_, _, half) = beams
    peak = whole.reaction_force.max()
    carrying = (whole.reaction_force >= 0.1 * peak).to_numpy()
    difference = np.abs(2 * half.reaction_force.to_numpy() - whole.reaction_force.to_numpy())[carrying]
    assert difference.max() < 0.005 * peak, pd.DataFrame({"whole": whole.reaction_force, "2 x half": 2 * half.reaction_force})


def test_the_specimen_table_against_a_published_curve(beams, paper_config):
    """The table of a specimen: the work of the load is the area under a curve (exact for a
    triangle), the half's force doubled by its scene's symmetry_factor, ratios against the curve."""
    from ifenn.studies.tables.metrics import work_of_load
    from ifenn.studies.tables.specimens import specimen_table, symmetry_factor

    u = np.linspace(0.0, 2.0, 21)
    triangle = np.minimum(u, 2.0 - u)  # peak 1 at u = 1, area 1
    assert abs(work_of_load(u, triangle, 2.0) - 1.0) < 1e-12 and abs(work_of_load(u, triangle, 0.5) - 0.125) < 1e-12
    published = pd.read_csv(paper_config["specimens"]["three-point-bending"]["measured"]["file"], comment="#")
    assert list(published.columns) == ["displacement_mm", "load_N"] and abs(published.load_N.max() - 34.75) < 1e-9
    (spec_whole, _, whole), (spec_half, _, half) = beams
    assert symmetry_factor(spec_whole["scene"]) == 1 and symmetry_factor(spec_half["scene"]) == 2
    doubled = half.assign(reaction_force=symmetry_factor(spec_half["scene"]) * half.reaction_force)
    table = specimen_table({"whole": whole, "half": doubled}, published).set_index("run")
    assert table.loc["measured", ["peak_ratio", "u_peak_ratio", "work_ratio"]].tolist() == [1.0, 1.0, 1.0]
    assert abs(table.loc["half", "peak_force"] / table.loc["whole", "peak_force"] - 1) < 0.005
    assert abs(table.loc["whole", "peak_ratio"] - whole.reaction_force.max() / 34.75) < 1e-12
