# Where the post-switch error of IFENN comes from: every source replayed on the FEM
# states saved after the switch-over (config 'error_sources'; ifenn.studies.drivers.error_sources).


rule error_sources:
    input:
        error_sources_inputs,
    output:
        table=report("results/tables/error_sources.csv", caption="../report/error_sources.rst", category="Tables"),
        states="results/tables/error_sources_states.csv",
        figure=report("results/figures/error_sources.png", caption="../report/error_sources.rst", category="IFENN runs"),
    params:
        cases=error_sources_cases,
        stagger_max_iterations=lambda w: config["error_sources"]["stagger_max_iterations"],
        crack_phi=lambda w: config["error_sources"]["crack_phi"],
        device=config["device"],  # where the network runs (ifenn.device)
    threads: 1
    resources:
        mem_mb=6000,
        runtime=120,
    conda:
        "../envs/ifenn.yaml"
    log:
        "logs/tables/error_sources.log",
    benchmark:
        "benchmarks/error_sources/error_sources.tsv"
    script:
        "../scripts/error_sources.py"
