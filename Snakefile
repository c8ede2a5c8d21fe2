# IFENN phase-field fracture workflow. `snakemake all` rebuilds every figure-level result.
# Data flows one way: config -> mesh -> FEM runs -> figures (PICNN and IFENN stages follow).
# Run from anywhere: snakemake -s REPO/Snakefile --directory DIR --configfile FILE TARGET
import os

from snakemake.utils import min_version

min_version("9.0")

# one pending scheduler wake-up at a time (Snakemake 9's timers multiply; ifenn/snakemake_patch.py)
from ifenn import snakemake_patch

snakemake_patch.apply()


configfile: os.path.join(workflow.basedir, "config", "config.yaml")


include: "workflow/rules/common.smk"


# Rules that only write a small JSON run on the submitting host, not as cluster jobs.
localrules:
    all,
    fem_spec,
    ifenn_spec,
    adaptive_spec,
    stability_cell_spec,



include: "workflow/rules/mesh.smk"
include: "workflow/rules/fem.smk"
include: "workflow/rules/training.smk"
include: "workflow/rules/ifenn.smk"
include: "workflow/rules/metrics.smk"
include: "workflow/rules/figures.smk"
include: "workflow/rules/stability.smk"
include: "workflow/rules/error_sources.smk"
include: "workflow/rules/whole_path.smk"
include: "workflow/rules/adaptive.smk"


rule all:
    input:
        "results/benchmarks/machine_speed.json",
        "results/summary.md",
        expand("results/mesh/{scene}.png", scene=config["scenes"]),
        expand("results/fem/{run}/history.csv", run=ALL_FEM_RUNS),
        expand("results/figures/fem/{run}_force_displacement.png", run=ALL_FEM_RUNS),
        "results/figures/training/training_data.png",
        "results/figures/training/training.png",
        "results/picnn/scores.csv",
        expand("results/figures/ifenn/{run}_force_displacement.png", run=config["ifenn_runs"]),
        "results/tables/accuracy.csv",
        "results/tables/timing.csv",
        "results/tables/process_zone.csv" if PROCESS_ZONE_PAIRS else [],
        expand("results/figures/paper/{run}_comparison.png", run=config["figures"]["comparisons"]),
        "results/figures/paper/views_3d.png",
        "results/figures/paper/mesh_study.png",
        "results/figures/paper/phase_field_time.png",
        expand("results/figures/specimens/{specimen}.png", specimen=config.get("specimens", {})),
        expand("results/tables/specimens/{specimen}.csv", specimen=config.get("specimens", {})),
        ["results/tables/stability.csv", "results/figures/stability_map.png"] if config.get("stability") else [],
        "results/tables/speed_accuracy.csv" if config.get("speed_accuracy") else [],
        expand("results/figures/speed_accuracy/{scene}.png", scene=config.get("speed_accuracy", {})),
        "results/benchmarks/phase_field_speed.csv" if config.get("phase_field_benchmark") else [],
        ["results/benchmarks/network_worth.csv", "results/figures/network_worth.png"] if config.get("network_worth") else [],
        ["results/tables/error_sources.csv", "results/figures/error_sources.png"] if config.get("error_sources") else [],
        "results/benchmarks/increment_speed.csv" if config.get("increment_benchmark") else [],
        ["results/tables/whole_path.csv", "results/figures/whole_path.png"] if config.get("whole_path") else [],
        ["results/tables/reference_convergence.csv", "results/figures/reference_convergence.png"] if config.get("reference_convergence") else [],
        ["results/benchmarks/whole_run_speed.csv", "results/figures/whole_run_speed.png"] if config.get("whole_run_benchmark") else [],
        ["results/tables/adaptive_resolution.csv", "results/figures/adaptive_resolution.png", "results/figures/adaptive_mesh.png"] if config.get("adaptive_resolution") else [],
