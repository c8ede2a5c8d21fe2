# Where the post-switch error of IFENN comes from (issue 12): every source replayed on the FEM
# states saved after the switch-over (config 'error_sources'; ifenn.error_sources).


def error_sources_cases(wildcards):
    """Per run: its spec, mesh, FEM run folder, published IFENN history and the network."""
    cases = []
    for run in config["error_sources"]["runs"]:
        fem_run = config["ifenn_runs"][run]["fem_run"]
        cases.append({"spec": f"results/ifenn/{run}/spec.json", "mesh": f"results/mesh/{config['fem_runs'][fem_run]['scene']}.xdmf",
                      "fem_dir": f"results/fem/{fem_run}", "ifenn_history": f"results/ifenn/{run}/history.csv",
                      "model": "results/picnn/model.pt"})
    return cases


def error_sources_inputs(wildcards):
    paths = set()
    for case in error_sources_cases(wildcards):
        paths |= {case["spec"], case["mesh"], case["ifenn_history"], case["model"],
                  f"{case['fem_dir']}/fields.h5", f"{case['fem_dir']}/history.csv"}
    return sorted(paths)


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
    threads: 1
    resources:
        mem_mb=6000,
        runtime=120,
    conda:
        "../envs/ifenn.yaml"
    log:
        "logs/tables/error_sources.log",
    benchmark:
        "benchmarks/error_sources.tsv"
    script:
        "../scripts/error_sources.py"
