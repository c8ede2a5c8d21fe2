"""The workflow through Snakemake: the quick profile end to end from another directory,
and a bad config value stopping everything before any job starts."""

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from ifenn.tooling.stage_times import parse_dry_run

REPO = Path(__file__).resolve().parents[1]
SNAKEMAKE = [sys.executable, "-m", "snakemake", "-s", str(REPO / "Snakefile")]
ENV = {**os.environ, "OMPI_ALLOW_RUN_AS_ROOT": "1", "OMPI_ALLOW_RUN_AS_ROOT_CONFIRM": "1", "OMP_NUM_THREADS": "1"}
# a guard against a hang, not a speed limit: CI's own limit (90 min); the suite must pass on a
# slow or busy machine
HANG_GUARD_S = 5400


def _snakemake(*args, cwd):
    return subprocess.run([*SNAKEMAKE, *args], cwd=cwd, env=ENV, capture_output=True, text=True, timeout=HANG_GUARD_S)


@pytest.fixture(scope="module")
def quick_workflow(tmp_path_factory):
    """The quick profile's `snakemake all` on 2 cores, once for the module (~5-6 min on a quiet
    2-core machine, longer on a busy one): the end-to-end check of every rule, and every test
    below reads its results (no tighter limit than the hang guard: a slow machine must pass)."""
    work = tmp_path_factory.mktemp("quick")
    result = _snakemake("--directory", str(work), "--configfile", str(REPO / "config" / "quick.yaml"),
                        "--cores", "2", "all", cwd=tmp_path_factory.getbasetemp())
    assert result.returncode == 0, result.stderr[-4000:]
    return work


def test_quick_profile_runs_end_to_end(quick_workflow):
    results = quick_workflow / "results"
    for run in ("snt1-I", "snt1-II", "snt1-III", "snt2-II", "snt3-II", "sdnt", "adnt"):
        history = pd.read_csv(results / "fem" / run / "history.csv")
        assert history.reaction_force.max() > 0
        assert (results / "figures" / "fem" / f"{run}_force_displacement.png").stat().st_size > 10_000
        assert (results / "fem" / run / "provenance.json").exists()
        hybrid = pd.read_csv(results / "ifenn" / run / "history.csv")
        assert len(hybrid) == len(history) and hybrid.hybrid_active.iloc[-1] == 1
    for scene in ("snt1", "snt2", "snt3", "sdnt", "adnt"):
        assert (results / "mesh" / f"{scene}.png").exists()
    accuracy = pd.read_csv(results / "tables" / "accuracy.csv")
    assert set(accuracy.run) >= {"snt1-I", "snt1-I-exact", "adnt"}
    timing = pd.read_csv(results / "tables" / "timing.csv")
    assert set(timing.method) == {"fem", "ifenn"}
    for figure in ("training/training_data.png", "training/training.png", "paper/views_3d.png", "paper/mesh_study.png",
                   "paper/phase_field_time.png", "paper/snt1-I_comparison.png", "paper/adnt_comparison.png",
                   "speed_accuracy/snt1.png", "speed_accuracy/three-point-bending.png", "stability_map.png",
                   "specimens/l-panel.png",
                   "specimens/three-point-bending.png"):
        assert (results / "figures" / figure).stat().st_size > 10_000, figure
    # the field's L-panel (a cut-out, a load on the cut-out's edge, plane stress, 100 mm thick): its
    # force in N peaks and falls as the panel cracks
    panel = pd.read_csv(results / "fem" / "l-panel" / "history.csv")
    assert panel.reaction_force.max() > 1000 and panel.reaction_force.iloc[-1] < 0.2 * panel.reaction_force.max()
    # the network trained on snt1's material serves the concrete at the same lc/h (its input scaled):
    # every method on the panel certified and at FEM's peak to 1 %
    for run in ("ifenn/l-panel-verified", "ifenn/l-panel-whole", "adaptive/l-panel-adaptive", "adaptive/l-panel-adaptive-verified"):
        other = pd.read_csv(results / run / "history.csv")
        assert abs(other.reaction_force.max() / panel.reaction_force.max() - 1) < 0.01, run
        if "verify_residual_after" in other:
            assert (other.verify_residual_after.dropna() <= 1e-3 * (1 + 1e-9)).all(), run
    # the three-point beam: every method at FEM's peak to 1 %, the half (doubled in the table) equal
    # to the whole, and the table's ratios are the runs' against the published curve's
    beam = pd.read_csv(results / "tables" / "specimens" / "three-point-bending.csv").set_index("run")
    published = beam.loc["measured"]
    assert published.peak_ratio == 1 and abs(published.peak_force - 34.75) < 1e-9
    fem = beam.loc["FEM three-point-bending"]
    whole = pd.read_csv(results / "fem" / "three-point-bending" / "history.csv")
    assert abs(fem.peak_force - whole.reaction_force.max()) < 1e-6 * fem.peak_force
    assert abs(fem.peak_ratio - fem.peak_force / published.peak_force) < 1e-8
    assert abs(beam.loc["FEM three-point-bending-half (x2)"].peak_force / fem.peak_force - 1) < 0.005
    for run in ("IFENN three-point-bending-verified", "IFENN three-point-bending-whole", "adaptive three-point-bending-adaptive",
                "adaptive three-point-bending-adaptive-verified"):
        assert abs(beam.loc[run].peak_force / fem.peak_force - 1) < 0.01, run
    # the numbers the docs quote come from this run: results/summary.md renders its tables and machine
    summary = (results / "summary.md").read_text()
    speed = pd.read_csv(results / "tables" / "speed_accuracy.csv")
    assert f"{speed.force_l2_rel_error.iloc[1]:.4g}" in summary and "(tables/speed_accuracy.csv)" in summary
    machine = __import__("json").loads((results / "benchmarks" / "machine_speed.json").read_text())
    assert f"{machine['kept_factor_apply_ms']} ms" in summary and "Not produced" not in summary


def test_paper_runs_do_not_move(quick_workflow):
    """The quick DAG's FEM, published IFENN, process-zone, verified, whole-path and adaptive runs
    compute what they computed before (tests/data/paper_runs/, written by tests/paper_runs.py): every
    column but the timings to 1e-10 relative on the processor that wrote them; elsewhere to 1e-6
    (another processor's BLAS kernels round differently, and a crack's growth carries it on)."""
    import numpy as np
    from paper_runs import REFERENCES, RUNS, compared_columns, machine, read

    same_machine = json.loads((REFERENCES / "machine.json").read_text()) == machine()
    rtol = 1e-10 if same_machine else 1e-6
    for kind, run in RUNS:
        reference = read(REFERENCES / kind / f"{run}.csv")
        history = read(quick_workflow / "results" / kind / run / "history.csv")
        assert compared_columns(history) == list(reference.columns), (kind, run)
        assert len(history) == len(reference), (kind, run, len(history), len(reference))
        for column in reference.columns:
            new, old = history[column].to_numpy(), reference[column].to_numpy()
            if old.dtype.kind in "fi" and new.dtype.kind in "fi":
                scale = np.nanmax(np.abs(old), initial=0.0)
                np.testing.assert_allclose(new, old, rtol=rtol, atol=rtol * scale, equal_nan=True, err_msg=f"{kind}/{run}: {column}")
            else:
                assert list(new) == list(old), (kind, run, column)


def test_quick_profile_speed_accuracy_stability_benchmark(quick_workflow):
    """Process-zone IFENN tracks full-image IFENN (force curve within 0.5 %) on every run of
    the quick profile; the speed/accuracy table, the stability CSV and the phase-field
    benchmark have a row for what the config names."""
    from ifenn.studies.tables.metrics import force_curve_error

    results = quick_workflow / "results"
    for run in ("snt1-I", "snt1-II", "snt1-III", "snt2-II", "snt3-II", "sdnt", "adnt"):
        full, zone = (pd.read_csv(results / "ifenn" / name / "history.csv") for name in (run, f"{run}-pz"))
        error = force_curve_error(zone.u.to_numpy(), zone.reaction_force.to_numpy(), full.u.to_numpy(), full.reaction_force.to_numpy())
        assert error < 0.005, (run, error)
    agreement = pd.read_csv(results / "tables" / "process_zone.csv").set_index("run")
    assert set(agreement.index) == {f"{run}-pz" for run in ("snt1-I", "snt1-II", "snt1-III", "snt2-II", "snt3-II", "sdnt", "adnt")}
    assert (agreement.force_l2_rel_error < 0.005).all() and (agreement.crack_iou > 0.9).all()
    # on these tiny images the windows of the single-notch runs cover most of the image (it is then
    # evaluated whole); the two-notch scenes use windows
    assert (agreement.evaluated_fraction_mean < 0.6).any() and (agreement.evaluated_fraction_mean <= 1).all()
    table = pd.read_csv(results / "tables" / "speed_accuracy.csv")
    assert {"snt1", "sdnt", "l-panel", "three-point-bending"} == set(table.scene) and table.is_reference.sum() == 4
    assert table.pareto_wall_s.any() and (table.force_l2_rel_error[~table.is_reference] > 0).all()
    # what the charts mark: per scene one reference (the is_reference row) and one baseline, a FEM run whose
    # wall the table divides by; the combined runs the config names (snt1, sdnt; none on the quick specimens)
    assert (table.role.fillna("") == "reference").equals(table.is_reference)
    for scene, rows in table.groupby("scene"):
        base = rows[rows.role == "baseline"]
        assert len(base) == 1 and base.method.iloc[0] == "fem", scene
        assert np.allclose(rows.wall_vs_baseline, rows.wall_s / base.wall_s.iloc[0]), scene
    assert set(table.run[table.role == "combined"]) == {"snt1-A-conv-adaptive", "snt1-A-conv-adaptive-verified",
                                                        "sdnt-A-conv-adaptive", "sdnt-A-conv-adaptive-verified"}
    # the work of the load's own front: per scene, the fastest run is on it, and no run on it is
    # beaten in both wall time and |work error| by another
    for _, rows in table[~table.is_reference].groupby("scene"):
        assert rows.pareto_work_wall_s[rows.wall_s.idxmin()]
        for _, r in rows[rows.pareto_work_wall_s].iterrows():
            assert not ((rows.wall_s < r.wall_s) & (rows.work_rel_error.abs() < abs(r.work_rel_error))).any()
    stability = pd.read_csv(results / "tables" / "stability.csv")
    assert set(stability.panel) == {"load step", "lc/h", "IFENN option"}
    assert set(stability.label) <= {"ok", "peak off", "crack path wrong", "no load drop", "diverged"}
    speed = pd.read_csv(results / "benchmarks" / "phase_field_speed.csv")
    # one row per method and device (FEM on PETSc: cpu; the IFENN methods also on CUDA where present)
    assert set(speed[speed.method == "fem"].device) == {"cpu"} and (speed.device == "cpu").sum() == 7 * speed.run.nunique()
    speed = speed[speed.device == "cpu"]
    assert set(speed.method) == {"fem", "ifenn_full_convolution", "ifenn_full", "ifenn_process_zone", "ifenn_verified",
                                 "ifenn_verified_network", "ifenn_verified_nonet"} and (speed.t_phase_field_s > 0).all()
    verified = speed[speed.method.str.startswith("ifenn_verified")]
    assert (verified.verify_residual_after_max <= 1e-3).all()
    # the orbit evaluation is the same network: the same forces as the convolutions
    final = speed.pivot(index="run", columns="method", values="final_force")
    assert ((final.ifenn_full - final.ifenn_full_convolution).abs() < 1e-3 * final.fem).all()
    # what a network is worth to the verified step: every warm start to the same certificate, the oracle corrects nothing
    from ifenn.studies.drivers.network_worth import VARIANTS

    worth = pd.read_csv(results / "benchmarks" / "network_worth.csv")
    assert set(worth.variant) == set(VARIANTS) and worth.run.nunique() == 3 and (worth.max_certificate <= 1e-3).all()
    assert (worth[worth.variant == "oracle everywhere"].cg_iterations == 0).all()
    assert (results / "figures" / "network_worth.png").stat().st_size > 10_000


def test_quick_profile_error_sources(quick_workflow):
    """The error split has every source of every configured run; its parts add up to the
    published step; replaying the published step on FEM's states lands near the whole run's error."""
    from ifenn.studies.drivers.error_sources import PUBLISHED_PARTS, SOURCES

    results = quick_workflow / "results"
    sources = pd.read_csv(results / "tables" / "error_sources.csv")
    assert set(sources.run) == {"snt1-II", "adnt"} and set(sources.source) == set(SOURCES)
    for _, rows in sources.groupby("run"):
        rows = rows.set_index("source")
        assert abs(rows.loc[list(PUBLISHED_PARTS), "force_mean"].sum() - rows.loc["published_step", "force_mean"]) < 1e-9
        assert (rows.states >= 2).all() and (rows.postswitch_rms_error > 0).all()
    states = pd.read_csv(results / "tables" / "error_sources_states.csv")
    assert (states[states.variant == "fem"].force_vs_fem == 0).all()
    assert (results / "figures" / "error_sources.png").stat().st_size > 10_000


def test_changing_an_ifenn_option_reruns_only_ifenn_and_its_dependents(quick_workflow, tmp_path):
    override = tmp_path / "override.yaml"
    override.write_text("ifenn:\n  smoothing_sigma: 1.0\n")
    result = _snakemake("--directory", str(quick_workflow), "--configfile", str(REPO / "config" / "quick.yaml"), str(override),
                        "-n", "--cores", "1", "--quiet", "rules", "all", cwd=quick_workflow)
    assert result.returncode == 0, result.stderr[-3000:]
    text = result.stdout + result.stderr
    rules = {line.split()[0] for line in text.splitlines() if line.strip() and line.split()[0].isidentifier() and len(line.split()) == 2}
    assert {"ifenn", "ifenn_spec", "accuracy_table"} <= rules, text
    assert not rules & {"fem", "fem_spec", "mesh", "train_picnn", "training_data"}, text


def test_instant_jobs_that_unlock_runs_come_first(tmp_path):
    """The paper DAG: every spec job (instant) has the top priority, so a run whose own priority
    is high (a long chain behind it) is not held back behind long jobs by its spec; a run that
    waits for another starts once it is free (fem_priority). Without it, in the
    paper DAG the snt1-II pair's spec ran 47 min after the network it waited for, FEM snt1-III behind the pair."""
    dry = _snakemake("--directory", str(tmp_path), "-n", "--forceall", "--cores", "2", "all", cwd=tmp_path)
    assert dry.returncode == 0, dry.stderr[-3000:]
    jobs = parse_dry_run(dry.stdout + dry.stderr)
    specs = [job for job in jobs if job["rule"].endswith("_spec")]
    assert {job["rule"] for job in specs} >= {"fem_spec", "ifenn_spec", "adaptive_spec", "stability_cell_spec"}
    assert all(job["priority"] == 100 for job in specs), [job for job in specs if job["priority"] != 100][:3]
    pairs = [job for job in jobs if job["rule"].startswith("whole_run_pair")]
    assert pairs and all(0 < job["priority"] <= 100 for job in pairs)


def test_adaptive_finer_references_replace_the_uniform_ones(tmp_path):
    """finer_references: adaptive: each finer reference of reference_convergence and
    adaptive_resolution is its adaptive run; `all` does not run the uniform ones (speed_accuracy's
    points snt1-III-fine and sdnt-fine become their adaptive runs too)."""
    override = tmp_path / "override.yaml"
    override.write_text("finer_references: adaptive\n")
    dry = _snakemake("--directory", str(tmp_path), "--configfile", str(REPO / "config" / "quick.yaml"), str(override),
                     "-n", "--cores", "1", "all", cwd=tmp_path)
    assert dry.returncode == 0, dry.stderr[-3000:]
    jobs = {(job["rule"], job["wildcards"]["run"]) for job in parse_dry_run(dry.stdout + dry.stderr) if "run" in job["wildcards"]}
    runs = {run for rule, run in jobs if rule == "fem"}
    adaptive = {run for rule, run in jobs if rule == "adaptive"}
    fines = {"snt1-II-fine", "snt1-III-fine", "sdnt-fine", "adnt-fine", "snt-shear-fine"}
    assert {f"{fine}-adaptive" for fine in fines} <= adaptive, adaptive
    assert not runs & fines, runs


def test_lint_and_slurm_profile_dry_run(tmp_path):
    lint = _snakemake("--directory", str(tmp_path), "--lint", cwd=tmp_path)
    assert "Congratulations" in lint.stdout + lint.stderr, lint.stdout[-3000:]
    dry = _snakemake("--directory", str(tmp_path), "--configfile", str(REPO / "config" / "quick.yaml"),
                     "--profile", str(REPO / "profiles" / "slurm"), "-n", "all", cwd=tmp_path)
    assert dry.returncode == 0, dry.stderr[-3000:]
    assert "fem" in dry.stdout


def test_stage_times_count_only_the_current_dag(quick_workflow):
    """stage-times sums the benchmark files of the jobs `all` has today: a file an older workflow
    left (a run since dropped) is named and left out, every job of the DAG is counted."""
    from ifenn.tooling.stage_times import dag_benchmarks, stage_times

    stale = quick_workflow / "benchmarks" / "fem" / "a-run-since-dropped.tsv"
    stale.write_text("s\tcpu_time\n9999.0\t9999.0\n")
    try:
        keep = dag_benchmarks(quick_workflow, REPO / "Snakefile", [str(REPO / "config" / "quick.yaml")])
        written = {str(p.relative_to(quick_workflow)) for p in (quick_workflow / "benchmarks").rglob("*.tsv")}
        assert "benchmarks/fem/snt1-I.tsv" in keep and "benchmarks/whole_run/snt1-II-whole.tsv" in keep and str(stale.relative_to(quick_workflow)) not in keep
        assert written - keep == {str(stale.relative_to(quick_workflow))}
        counted, every = stage_times(quick_workflow, keep).set_index("stage"), stage_times(quick_workflow).set_index("stage")
        assert every.loc["fem", "wall_s"] - counted.loc["fem", "wall_s"] == pytest.approx(9999.0, abs=0.1)
        assert counted.loc["total", "jobs"] == len(keep & written)
        shown = subprocess.run([sys.executable, "-m", "ifenn", "stage-times", str(quick_workflow), "--top", "3", "--configfile",
                                str(REPO / "config" / "quick.yaml")], env=ENV, capture_output=True, text=True, timeout=600)
        assert shown.returncode == 0 and "left out: 1 benchmark files" in shown.stdout and "a-run-since-dropped" in shown.stdout
        assert "not run yet" not in shown.stdout and "the 3 longest jobs" in shown.stdout
        # the DAG's first job measured the machine, and stage-times quotes it
        assert "one apply of its kept Cholesky factor" in shown.stdout, shown.stdout
        # the longest chain of jobs that wait for each other: at least the longest job, at most all jobs
        chain = re.search(r"the longest chain: ([\d.]+) min: (.+)", shown.stdout)
        assert chain and " -> " in chain.group(2), shown.stdout
        total = counted.loc["total"]
        assert total.longest_s - 3 <= 60 * float(chain.group(1)) <= total.wall_s + 3
    finally:
        stale.unlink()


def test_report_bundles_every_figure(quick_workflow):
    result = _snakemake("--directory", str(quick_workflow), "--configfile", str(REPO / "config" / "quick.yaml"),
                        "--report", "report.html", cwd=quick_workflow)
    assert result.returncode == 0, result.stderr[-3000:]
    assert (quick_workflow / "report.html").stat().st_size > 1_000_000


def test_rerun_has_nothing_to_do(quick_workflow):
    result = _snakemake("--directory", str(quick_workflow), "--configfile", str(REPO / "config" / "quick.yaml"),
                        "-n", "--cores", "1", "all", cwd=quick_workflow)
    assert result.returncode == 0
    assert "Nothing to be done" in result.stdout + result.stderr


def test_bad_config_fails_before_any_job(tmp_path):
    override = tmp_path / "bad.yaml"
    override.write_text("material:\n  Gc: -2.7\n")
    result = _snakemake("--directory", str(tmp_path), "--configfile", str(REPO / "config" / "quick.yaml"), str(override),
                        "--cores", "1", "all", cwd=tmp_path)
    assert result.returncode != 0
    assert "material.Gc" in result.stderr and "-2.7 is less than or equal to the minimum of 0" in result.stderr
    assert not (tmp_path / "results").exists()


def test_quick_profile_verified_runs_track_fem(quick_workflow):
    """Verified IFENN on the seven quick runs: every hybrid increment certified (max |r| within
    the tolerance), and after the switch-over the force tracks FEM within 1 % of its peak (RMS),
    where the published step is off by several percent on most runs."""
    from ifenn.studies.tables.metrics import post_switch_force_error

    results = quick_workflow / "results"
    for run in ("snt1-I", "snt1-II", "snt1-III", "snt2-II", "snt3-II", "sdnt", "adnt"):
        fem = pd.read_csv(results / "fem" / run / "history.csv")
        published, verified = (pd.read_csv(results / "ifenn" / name / "history.csv") for name in (run, f"{run}-verified"))
        hybrid = verified[verified.hybrid_active == 1]
        assert len(hybrid) > 0 and (hybrid.verify_residual_after <= 1e-3).all(), run
        error = post_switch_force_error(fem, verified)["post_switch_rms_error"]
        assert error < 0.01, (run, error)
        assert error < post_switch_force_error(fem, published)["post_switch_rms_error"], run


def test_quick_profile_whole_path(quick_workflow):
    """Whole-path IFENN through the DAG: the seven whole-path runs (IFENN from the first increment, no
    hybrid_active 0 row) compared with their FEM runs (on the quick scene all four targets are met:
    peaks within 0.1 % of FEM at h; adnt and the shear scene within 0.15 %: with their slits cut in
    the pixel equation adnt's peak is 0.14 % below FEM's, snt-shear's 0.12 %), the pre-nucleation
    replay, and the whole-run benchmark with a row per run and method; the speed-accuracy table has
    the whole-path points."""
    results = quick_workflow / "results"
    table = pd.read_csv(results / "tables" / "whole_path.csv").set_index("run")
    assert set(table.index) == {f"{run}-whole" for run in ("snt1-I", "snt1-II", "snt1-III", "snt2-II", "snt3-II", "sdnt", "adnt",
                                                           "snt-shear")}
    assert (table.hybrid_increments == table.increments_fem).all() and (table.peak_force_rel_error.abs() < 0.0015).all()
    assert (table.drop(index=["adnt-whole", "snt-shear-whole"]).peak_force_rel_error.abs() < 0.001).all()
    # snt-shear-whole misses the post-peak RMS target against FEM at h (2.05 % of the peak, measured),
    # where FEM at h is itself 1.24 % off the finer FEM and the whole path 0.86 %: the reference
    # convergence test holds it to the finer reference instead
    paper = table.drop(index="snt-shear-whole")
    assert paper.meets_all.all() and table.loc["snt-shear-whole", ["meets_peak_force", "meets_u_peak", "meets_final_force"]].all()
    network = pd.read_csv(results / "tables" / "pre_nucleation.csv")
    assert (network.stage == "pre_nucleation").sum() >= 3 and (network.network_residual_max >= network.network_max_abs_error).all()
    speed = pd.read_csv(results / "benchmarks" / "whole_run_speed.csv")
    assert (speed.device == "cpu").sum() == 6 and set(speed.method) == {"fem", "ifenn"} and (speed.t_phase_field_total_s > 0).all()
    assert (results / "figures" / "whole_run_speed.png").stat().st_size > 10_000
    assert (results / "figures" / "whole_path.png").stat().st_size > 10_000
    points = pd.read_csv(results / "tables" / "speed_accuracy.csv")
    assert points.variant.str.endswith("whole path").sum() == 6   # snt1 I-III, sdnt, the L-panel, the beam


def test_quick_profile_reference_convergence(quick_workflow):
    """Through the DAG, on the quick scenes (against twice the elements): FEM at h misses the finer
    FEM after the peak (measured 1.0 / 0.9 / 1.6 / 1.7 / 1.2 % of the peak on snt1-II / snt1-III / sdnt /
    adnt / snt-shear), every whole-path run is nearer the finer FEM than FEM at h is (0.29-0.86 %), and so is
    every verified snt1 run (0.64-0.85 %): the pixel equation on the Gauss-point grid resolves the
    phase field at h/2. A verified run that switches late follows FEM at h after the switch (adnt:
    0.03 % apart) and is then as far from the finer FEM as FEM is, never farther. Paper scale: docs/decisions.md."""
    table = pd.read_csv(results := quick_workflow / "results" / "tables" / "reference_convergence.csv", keep_default_na=False)
    assert set(table.case) == {"snt1-II", "snt1-III", "sdnt", "adnt", "snt-shear", "l-panel", "three-point-bending"}
    # the quick L-panel (lc a ninth of the panel: the damage spreads from the clamped foot, measured
    # 0.44 / 0.69 / 0.82 % for FEM / verified / whole path) does not rank discretisations; each of its
    # methods is within 1 % of the finer FEM after the peak
    panel = table[table.case == "l-panel"]
    assert len(panel) == 3 and (panel.rms_vs_fine < 0.01).all()
    table = table[table.case != "l-panel"]
    fem = table[table.method == "fem"].set_index("case")
    assert (fem.rms_vs_fine > 0.003).all() and (fem.peak_force_fine < fem.peak_force).all()  # a coarser AT2 mesh is tougher
    runs = table[table.method == "ifenn"]
    assert set(runs.run) == {f"{case}-{kind}" for case in fem.index for kind in ("verified", "whole")}
    fem_rms = fem.loc[runs.case, "rms_vs_fine"].to_numpy()
    assert (runs.rms_vs_fine.to_numpy() <= fem_rms + 1e-3).all()
    whole, snt1 = runs.run.str.endswith("-whole").to_numpy(), runs.case.str.startswith("snt1").to_numpy()
    assert runs[whole | snt1].closer_to_fine.all() and (runs.rms_vs_fine.to_numpy() < fem_rms)[whole | snt1].all()
    assert (results.parent.parent / "figures" / "reference_convergence.png").stat().st_size > 10_000


def test_quick_profile_adaptive_resolution(quick_workflow):
    """Through the DAG: the adaptive runs of snt1-II (the certified pixel solve, and the verified
    IFENN step on the same mesh), snt1-III, sdnt, adnt (two cracks that merge) and snt-shear against
    the finer uniform FEM: peak within 0.5 % and post-peak RMS
    within 1 % of the finer peak (measured 0.08 % and 0.17-0.19 %), nearer than FEM at h (0.42 %,
    1.02 %); the two adaptive methods agree to the verified step's certificate. The quick scene's
    lc is a sixth of the specimen, so its fine region soon covers it: the dofs and wall targets are
    judged at the paper's scale (docs/decisions.md)."""
    results = quick_workflow / "results"
    table = pd.read_csv(results / "tables" / "adaptive_resolution.csv").set_index("run")
    assert set(table.method) == {"fem-uniform", "fem-adaptive", "verified-adaptive"}
    assert set(table.case) == {"snt1-II", "snt1-III", "sdnt", "adnt", "snt-shear", "l-panel", "three-point-bending"}
    # the quick L-panel (a cut-out): both adaptive methods nearer the finer FEM's peak than FEM at h
    # (measured 0.28 against 0.70 %) and within 1 % after it
    panel = table[table.case == "l-panel"]
    for run in ("l-panel-adaptive", "l-panel-adaptive-verified"):
        assert abs(panel.loc[run].peak_error_vs_fine_pct) < abs(panel.loc["l-panel"].peak_error_vs_fine_pct)
        assert panel.loc[run].post_peak_rms_vs_fine_pct < 1.0 and panel.loc[run].increments_outside_fine == 0
    # its finest displacement cells at h (phi on the same h/2 pixels): fewer dofs than at h/2, the
    # crack kept in fine cells, the peak within the specimen target's 1 % of the finer FEM's (quick:
    # measured 0.85 %, FEM at h 0.70 %; at the paper's scale +0.05 % of the finer reference)
    cells_h, fine_cells = panel.loc["l-panel-adaptive-verified-cells-h"], panel.loc["l-panel-adaptive-verified"]
    assert cells_h.increments_outside_fine == 0 and cells_h.dofs_fraction_of_fine < fine_cells.dofs_fraction_of_fine
    assert abs(cells_h.peak_error_vs_fine_pct) < 1.0
    # the quick beam: both adaptive methods nearer the finer FEM than FEM at h in peak and in the work
    # of the load (measured 0.91 against 1.55 %, 0.93 against 2.89 %); u at the peak one load step
    # off (4 %: the quick schedule's step is 2e-3 mm)
    beam = table[table.case == "three-point-bending"]
    for run in ("three-point-bending-adaptive", "three-point-bending-adaptive-verified"):
        row, fem = beam.loc[run], beam.loc["three-point-bending"]
        assert abs(row.peak_error_vs_fine_pct) < abs(fem.peak_error_vs_fine_pct) and abs(row.work_error_vs_fine_pct) < abs(fem.work_error_vs_fine_pct)
    for case in ("snt1-III", "sdnt", "adnt"):   # measured: peak 0.02 / 0.08 / 0.09 %, RMS 0.18-0.21 / 0.38 / 0.35 % (FEM at h 0.9-1.7 %)
        fem = table.loc[case]
        for row in (table.loc[f"{case}-adaptive"], table.loc[f"{case}-adaptive-verified"]):
            assert abs(row.peak_error_vs_fine_pct) < 0.5 and row.post_peak_rms_vs_fine_pct < 0.6 * fem.post_peak_rms_vs_fine_pct
    uniform, exact, verified = table.loc["snt1-II"], table.loc["snt1-II-adaptive"], table.loc["snt1-II-adaptive-verified"]
    shear, shear_uniform = table.loc["snt-shear-adaptive"], table.loc["snt-shear"]
    # the verified step certifies FEM's (uncapped) equation by default; the capped variant is named
    uncapped, capped = table.loc["snt-shear-adaptive-verified"], table.loc["snt-shear-adaptive-verified-capped"]
    assert shear.post_peak_rms_vs_fine_pct < shear_uniform.post_peak_rms_vs_fine_pct
    assert uncapped.post_peak_rms_vs_fine_pct < shear_uniform.post_peak_rms_vs_fine_pct and abs(uncapped.peak_error_vs_fine_pct) < 0.5
    assert abs(capped.peak_error_vs_fine_pct) < 0.5
    for row in (exact, verified, shear):
        assert abs(row.peak_error_vs_fine_pct) < 0.5 and row.post_peak_rms_vs_fine_pct < 1.0
        assert row.post_peak_rms_vs_fine_pct < uniform.post_peak_rms_vs_fine_pct
        assert row.increments_outside_fine == 0 and row.remeshes > 0
    assert abs(exact.peak_force - verified.peak_force) < 1e-3 * exact.peak_force
    for figure in ("adaptive_resolution.png", "adaptive_mesh.png"):
        assert (results / "figures" / figure).stat().st_size > 10_000
    # the adaptive runs are points of the chart, and so are its references: converged staggering on
    # the finest schedule on the adaptive mesh at the finer FEM's spacing. Against them converged
    # staggering at h errs by its mesh (measured 0.11-0.14 of the force curve's L2 norm on snt1, 0.017
    # on sdnt), single pass on these coarse load steps by its lag after the peak (0.65-0.75), on the
    # finer uniform mesh too (0.68, 0.70)
    points = pd.read_csv(results / "tables" / "speed_accuracy.csv").set_index("run")
    adaptive = points[points.method == "adaptive"]
    assert len(adaptive) == 19 and adaptive.variant.str.startswith("adaptive mesh").all()
    assert (adaptive.displacement_solves >= adaptive.increments).all()
    references = {"snt1-III-conv-adaptive", "sdnt-conv-adaptive", "l-panel-conv-adaptive", "three-point-bending-conv-adaptive"}
    assert set(points.index[points.is_reference]) == references and set(points.reference) == references
    reference = points[points.is_reference]
    assert (reference.force_l2_rel_error == 0).all() and (reference.post_peak_rms == 0).all()
    fem_points = points[points.method == "fem"]
    for converged, single in (("snt1-III-conv", "snt1-III"), ("snt1-II-conv", "snt1-II"), ("sdnt-conv", "sdnt"),
                              ("snt1-III-conv", "snt1-III-fine"), ("sdnt-conv", "sdnt-fine")):
        assert fem_points.loc[converged, "force_l2_rel_error"] < 0.5 * fem_points.loc[single, "force_l2_rel_error"], converged
    # converged staggering with the verified step follows FEM's converged path; the plain network
    # does not localise at a held load and creeps (quick: 0.112 / 0.117 / 0.431 of the force curve's
    # L2 norm for verified / FEM / plain; paper scale 0.173 / 0.173 / 0.304)
    # (the plain converged point is on schedule II only; I and III have the verified one)
    ifenn_points = points[points.method == "ifenn"]
    assert {"snt1-I-conv", "snt1-III-conv"}.isdisjoint(ifenn_points.index)
    for schedule in ("I", "II", "III"):
        verified_conv, fem_conv = ifenn_points.loc[f"snt1-{schedule}-conv-verified"], fem_points.loc[f"snt1-{schedule}-conv"]
        assert verified_conv.converged and verified_conv.stagger_iterations > verified_conv.increments
        assert abs(verified_conv.force_l2_rel_error - fem_conv.force_l2_rel_error) < 0.2 * fem_conv.force_l2_rel_error, schedule
    plain_conv = ifenn_points.loc["snt1-II-conv"]
    assert plain_conv.force_l2_rel_error > 1.5 * ifenn_points.loc["snt1-II-conv-verified", "force_l2_rel_error"]
    # the combined runs (adaptive steps, converged staggering, the adaptive mesh, the certified or the
    # verified step) end on the converged reference's curve: the half drop within 3 % of its u and the
    # work of the load within 8 % (quick, measured 0.7 / 2.0 % and 3.4 / 6.0 % on snt1 / sdnt; the
    # single pass of schedule II: 38 / 42 % and 69 / 58 %), and undo and redo steps as the controller says
    for scene in ("snt1", "sdnt"):
        for run in (f"{scene}-A-conv-adaptive", f"{scene}-A-conv-adaptive-verified"):
            point = adaptive.loc[run]
            assert abs(point.u_half_drop_rel_error) < 0.03 and abs(point.work_rel_error) < 0.08, run
            assert point.displacement_solves > point.stagger_iterations > point.increments, run
    # the reference one level finer (phi and the finest cells at h/4): how far "converged" is from
    # converged, nearer the reference than any other point (quick, measured 1.6 % L2, -1.2 % work)
    finer = adaptive.loc["snt1-III-conv-finer-adaptive"]
    others = points[(points.scene == "snt1") & ~points.is_reference].drop(index="snt1-III-conv-finer-adaptive", errors="ignore")
    assert finer.force_l2_rel_error < min(0.03, others.force_l2_rel_error.min()) and abs(finer.work_rel_error) < 0.02
