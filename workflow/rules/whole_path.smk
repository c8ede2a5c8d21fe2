# IFENN over the whole load path: the whole-path runs (switch_over 'start') against the
# FEM run of the same scene and schedule, what the network makes of the pre-nucleation damage, and
# the phase-field step over the whole run, FEM against whole-path IFENN (ifenn.studies.whole_path,
# ifenn.studies.whole_run_benchmark).


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


rule whole_run_benchmark:
    input:
        ifenn_specs=lambda w: [f"results/ifenn/{r}/spec.json" for r in config["whole_run_benchmark"]["runs"]],
        meshes=lambda w: sorted({f"results/mesh/{config['fem_runs'][config['ifenn_runs'][r]['fem_run']]['scene']}.xdmf"
                                 for r in config["whole_run_benchmark"]["runs"]}),
        model="results/picnn/model.pt",
    output:
        summary=report("results/benchmarks/whole_run_speed.csv", caption="../report/whole_run_speed.rst", category="Whole load path"),
        increments="results/benchmarks/whole_run_speed_increments.csv",
    params:
        python=PYTHON,
        script=os.path.join(workflow.basedir, "benchmarks", "whole_run_speed.py"),
        increments=lambda w: (f"--increments {config['whole_run_benchmark']['increments']}"
                              if config["whole_run_benchmark"].get("increments") else ""),
    # config benchmarks_alone: all cores, nothing else runs while it measures (it uses one)
    threads: benchmark_cores
    resources:
        runtime=480,
    conda:
        "../envs/ifenn.yaml"
    log:
        "logs/benchmarks/whole_run_speed.log",
    benchmark:
        "benchmarks/speed/whole_run_speed.tsv"
    shell:
        "OMP_NUM_THREADS=1 {params.python} {params.script} --model {input.model} --specs {input.ifenn_specs}"
        " {params.increments} --out {output.summary} --out-increments {output.increments} > {log} 2>&1"


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
