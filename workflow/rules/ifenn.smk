# IFENN runs: each continues a FEM run from its switch-over increment with the PICNN (or the
# exact pixel solver), then is compared with it; whole-path runs (switch_over 'start') compute
# every increment themselves and need no FEM state.


rule ifenn_spec:
    output:
        "results/ifenn/{run}/spec.json",
    params:
        spec=lambda w: json.dumps(ifenn_run_spec(config, w.run), sort_keys=True),
    priority: 100  # instant; unlocks its run, whose own priority counts only once it is ready (fem.smk)
    log:
        "logs/ifenn/{run}_spec.log",
    benchmark:
        "benchmarks/specs/ifenn_{run}.tsv"
    conda:
        "../envs/ifenn.yaml"
    script:
        "../scripts/write_spec.py"


rule ifenn:
    wildcard_constraints:
        run=run_pattern(PAIRED_RUNS.values()),  # the whole-run benchmark's runs: rule whole_run_pair
    input:
        unpack(ifenn_inputs),
    output:
        history="results/ifenn/{run}/history.csv",
        fields="results/ifenn/{run}/fields.h5",
        xdmf="results/ifenn/{run}/paraview.xdmf",
        xdmf_h5="results/ifenn/{run}/paraview.h5",
        provenance="results/ifenn/{run}/provenance.json",
    params:
        python=PYTHON,
        device=config["device"],  # where the network runs (ifenn.device)
        model=lambda w, input: f"--model {input.model}" if "model" in input.keys() else "",
        # a whole-path run (switch_over 'start') gets its FEM run's folder too, and does not read it
        fem_dir=lambda w, input: (os.path.dirname(input.fem_history) if "fem_history" in input.keys()
                                  else f"results/fem/{config['ifenn_runs'][w.run]['fem_run']}"),
        out=lambda w, output: os.path.dirname(output.history),
    threads: 1
    resources:
        mem_mb=4000,
        runtime=240,
    conda:
        "../envs/ifenn.yaml"
    log:
        "logs/ifenn/{run}.log",
    benchmark:
        "benchmarks/ifenn/{run}.tsv"
    shell:
        "OMP_NUM_THREADS=1 {params.python} -m ifenn ifenn --spec {input.spec} --mesh {input.mesh} --device {params.device}"
        " --fem-dir {params.fem_dir} {params.model} --out {params.out} > {log} 2>&1"


rule ifenn_force_figure:
    input:
        ifenn="results/ifenn/{run}/history.csv",
        fem=lambda w: f"results/fem/{config['ifenn_runs'][w.run]['fem_run']}/history.csv",
    output:
        report("results/figures/ifenn/{run}_force_displacement.png", caption="../report/ifenn_force.rst", category="IFENN runs"),
    params:
        fem_run=lambda w: config["ifenn_runs"][w.run]["fem_run"],
    conda:
        "../envs/ifenn.yaml"
    log:
        "logs/figures/ifenn_{run}.log",
    benchmark:
        "benchmarks/figures/ifenn_{run}.tsv"
    script:
        "../scripts/ifenn_force_figure.py"
