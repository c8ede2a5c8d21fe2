# IFENN over the whole load path: the whole-path runs (switch_over 'start') against the
# FEM run of the same scene and schedule, what the network makes of the pre-nucleation damage, and
# the phase-field step over the whole run, FEM against whole-path IFENN (ifenn.studies.drivers.whole_path,
# ifenn.studies.drivers.whole_run_benchmark).


rule whole_path_table:
    input:
        whole_path_inputs,
    output:
        table=report("results/tables/whole_path.csv", caption="../report/whole_path.rst", category="Whole load path"),
        network=report("results/tables/pre_nucleation.csv", caption="../report/whole_path.rst", category="Whole load path"),
        figure=report("results/figures/whole_path.png", caption="../report/whole_path.rst", category="Whole load path"),
    params:
        runs=lambda w: whole_path_dirs(),
        network_cases=lambda w: whole_path_network_cases(),
        targets=lambda w: config["whole_path"]["targets"],
        device=config["device"],  # where the network runs (ifenn.device)
    threads: 1
    conda:
        "../envs/ifenn.yaml"
    log:
        "logs/tables/whole_path.log",
    benchmark:
        "benchmarks/tables/whole_path.tsv"
    script:
        "../scripts/whole_path_table.py"


# The whole-run benchmark's runs: each whole-path run and its FEM run computed together, one
# process, increments interleaved (`python -m ifenn pair`), writing both run directories (the rules
# fem and ifenn leave these runs to it) and the benchmark's rows: the runs are computed once.
RUN_FILES = ("history.csv", "fields.h5", "paraview.xdmf", "paraview.h5", "provenance.json")

for _fem_run, _whole_run in PAIRED_RUNS.items():

    rule:
        name:
            f"whole_run_pair_{identifier(_whole_run)}"
        input:
            fem_spec=f"results/fem/{_fem_run}/spec.json",
            ifenn_spec=f"results/ifenn/{_whole_run}/spec.json",
            mesh=f"results/mesh/{config['fem_runs'][_fem_run]['scene']}.xdmf",
            model="results/picnn/model.pt",
        output:
            **{f"fem_{name.replace('.', '_')}": f"results/fem/{_fem_run}/{name}" for name in RUN_FILES},
            **{f"ifenn_{name.replace('.', '_')}": f"results/ifenn/{_whole_run}/{name}" for name in RUN_FILES},
            table=f"results/benchmarks/whole_run/{_whole_run}.csv",
            increments=f"results/benchmarks/whole_run/{_whole_run}_increments.csv",
        params:
            python=PYTHON,
            device=config["device"],  # where the network runs (ifenn.device)
            fem_out=lambda w, output: os.path.dirname(output.fem_history_csv),
            ifenn_out=lambda w, output: os.path.dirname(output.ifenn_history_csv),
            increments=(f"--increments {config['whole_run_benchmark']['increments']}"
                        if config["whole_run_benchmark"].get("increments") else ""),
        threads: 1
        # the longest jobs of the DAG: as early as the network allows (common.smk fem_priority)
        priority: fem_priority(SimpleNamespace(run=_fem_run))
        resources:
            mem_mb=6000,
            runtime=480,
        conda:
            "../envs/ifenn.yaml"
        log:
            f"logs/whole_run/{_whole_run}.log",
        benchmark:
            f"benchmarks/whole_run/{_whole_run}.tsv"
        shell:
            "OMP_NUM_THREADS=1 {params.python} -m ifenn pair --fem-spec {input.fem_spec} --ifenn-spec {input.ifenn_spec}"
            " --mesh {input.mesh} --model {input.model} --device {params.device} --fem-out {params.fem_out}"
            " --ifenn-out {params.ifenn_out} {params.increments} --table {output.table}"
            " --increments-table {output.increments} > {log} 2>&1"


rule whole_run_benchmark:
    # the rows of every pair (rule whole_run_pair_*) in one table
    input:
        tables=[f"results/benchmarks/whole_run/{run}.csv" for run in PAIRED_RUNS.values()],
        increments=[f"results/benchmarks/whole_run/{run}_increments.csv" for run in PAIRED_RUNS.values()],
    output:
        summary=report("results/benchmarks/whole_run_speed.csv", caption="../report/whole_run_speed.rst", category="Whole load path"),
        increments="results/benchmarks/whole_run_speed_increments.csv",
    conda:
        "../envs/ifenn.yaml"
    log:
        "logs/benchmarks/whole_run_speed.log",
    benchmark:
        "benchmarks/tables/whole_run_speed.tsv"
    script:
        "../scripts/whole_run_speed_table.py"


rule whole_run_speed_figure:
    input:
        summary="results/benchmarks/whole_run_speed.csv",
        increments="results/benchmarks/whole_run_speed_increments.csv",
    output:
        report("results/figures/whole_run_speed.png", caption="../report/whole_run_speed.rst", category="Whole load path"),
    conda:
        "../envs/ifenn.yaml"
    log:
        "logs/figures/whole_run_speed.log",
    benchmark:
        "benchmarks/figures/whole_run_speed.tsv"
    script:
        "../scripts/whole_run_speed_figure.py"
