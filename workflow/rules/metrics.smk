# Accuracy and timing tables: every IFENN run against the FEM run it continues.


rule accuracy_table:
    input:
        ifenn=expand("results/ifenn/{run}/{name}", run=config["ifenn_runs"], name=("fields.h5", "history.csv", "spec.json")),
        fem=lambda w: sorted({f"results/fem/{r['fem_run']}/{name}" for r in config["ifenn_runs"].values()
                              for name in ("fields.h5", "history.csv", "spec.json")}),
    output:
        report("results/tables/accuracy.csv", caption="../report/accuracy.rst", category="Tables"),
    params:
        runs=run_pairs(),
    conda:
        "../envs/ifenn.yaml"
    log:
        "logs/tables/accuracy.log",
    benchmark:
        "benchmarks/tables/accuracy.tsv"
    script:
        "../scripts/accuracy_table.py"


rule timing_table:
    input:
        ifenn=expand("results/ifenn/{run}/history.csv", run=config["ifenn_runs"]),
        fem=lambda w: sorted({f"results/fem/{r['fem_run']}/history.csv" for r in config["ifenn_runs"].values()}),
    output:
        report("results/tables/timing.csv", caption="../report/timing.rst", category="Tables"),
    params:
        runs=run_pairs(),
    conda:
        "../envs/ifenn.yaml"
    log:
        "logs/tables/timing.log",
    benchmark:
        "benchmarks/tables/timing.tsv"
    script:
        "../scripts/timing_table.py"


rule process_zone_table:
    input:
        lambda w: [f"results/ifenn/{r}/{f}" for pair in PROCESS_ZONE_PAIRS.items() for r in pair for f in ("history.csv", "fields.h5")],
    output:
        report("results/tables/process_zone.csv", caption="../report/process_zone.rst", category="Tables"),
    params:
        pairs={zone: {"full_run": full, "zone_dir": f"results/ifenn/{zone}", "full_dir": f"results/ifenn/{full}"}
               for zone, full in PROCESS_ZONE_PAIRS.items()},
    conda:
        "../envs/ifenn.yaml"
    log:
        "logs/tables/process_zone.log",
    benchmark:
        "benchmarks/tables/process_zone.tsv"
    script:
        "../scripts/process_zone_table.py"


rule speed_accuracy:
    input:
        runs=speed_accuracy_inputs,
        benchmark="results/benchmarks/phase_field_speed.csv",
    output:
        table=report("results/tables/speed_accuracy.csv", caption="../report/speed_accuracy.rst", category="Speed and accuracy"),
        figures=[report(f"results/figures/speed_accuracy/{scene}.png", caption="../report/speed_accuracy.rst", category="Speed and accuracy")
                 for scene in config.get("speed_accuracy", {})],
    params:
        setups=speed_accuracy_setups(config),
        run_dirs=lambda w: speed_accuracy_dirs(),
    conda:
        "../envs/ifenn.yaml"
    log:
        "logs/tables/speed_accuracy.log",
    benchmark:
        "benchmarks/tables/speed_accuracy.tsv"
    script:
        "../scripts/speed_accuracy.py"


rule machine_speed:
    """The machine the DAG's benchmark files were measured on (benchmarks/machine_speed.py): alone,
    first (every core, the highest priority), ~10 s; stage-times prints it beside the sums."""
    output:
        "results/benchmarks/machine_speed.json",
    params:
        python=PYTHON,
        script=os.path.join(workflow.basedir, "benchmarks", "machine_speed.py"),
    threads: all_cores
    priority: 200
    conda:
        "../envs/ifenn.yaml"
    log:
        "logs/benchmarks/machine_speed.log",
    benchmark:
        "benchmarks/machine/machine_speed.tsv"
    shell:
        "OMP_NUM_THREADS=1 {params.python} {params.script} --out {output} > {log} 2>&1"


rule phase_field_benchmark:
    input:
        ifenn_specs=lambda w: [f"results/ifenn/{r}/spec.json" for r in config["phase_field_benchmark"]["runs"]],
        fem=lambda w: [f"results/fem/{config['ifenn_runs'][r]['fem_run']}/fields.h5" for r in config["phase_field_benchmark"]["runs"]],
        model="results/picnn/model.pt",
    output:
        report("results/benchmarks/phase_field_speed.csv", caption="../report/phase_field_speed.rst", category="Speed and accuracy"),
    params:
        python=PYTHON,
        script=os.path.join(workflow.basedir, "benchmarks", "phase_field_speed.py"),
        increments=config.get("phase_field_benchmark", {}).get("increments", 40),
        zone=lambda w: json.dumps(json.dumps(config["ifenn"]["process_zone"])),
        verification=lambda w: json.dumps(json.dumps(config["ifenn"]["verification"])),
    # config benchmarks_alone: all cores, nothing else runs while it measures (it uses one)
    threads: benchmark_cores
    conda:
        "../envs/ifenn.yaml"
    log:
        "logs/benchmarks/phase_field_speed.log",
    benchmark:
        "benchmarks/speed/phase_field_speed.tsv"
    shell:
        "OMP_NUM_THREADS=1 {params.python} {params.script} --model {input.model}"
        " --specs {input.ifenn_specs} --increments {params.increments} --process-zone {params.zone}"
        " --verification {params.verification} --out {output} > {log} 2>&1"


rule network_worth_benchmark:
    input:
        ifenn_specs=lambda w: [f"results/ifenn/{r}/spec.json" for r in config["network_worth"]["runs"]],
        fem=lambda w: [f"results/fem/{config['ifenn_runs'][r]['fem_run']}/fields.h5" for r in config["network_worth"]["runs"]],
        model="results/picnn/model.pt",
    output:
        table=report("results/benchmarks/network_worth.csv", caption="../report/network_worth.rst", category="Speed and accuracy"),
        increments="results/benchmarks/network_worth_increments.csv",
        figure=report("results/figures/network_worth.png", caption="../report/network_worth.rst", category="Speed and accuracy"),
    params:
        python=PYTHON,
        script=os.path.join(workflow.basedir, "benchmarks", "network_worth.py"),
        increments=config.get("network_worth", {}).get("increments", 40),
    # config benchmarks_alone: all cores, nothing else runs while it measures (it uses one)
    threads: benchmark_cores
    conda:
        "../envs/ifenn.yaml"
    log:
        "logs/benchmarks/network_worth.log",
    benchmark:
        "benchmarks/speed/network_worth.tsv"
    shell:
        "OMP_NUM_THREADS=1 {params.python} {params.script} --model {input.model} --specs {input.ifenn_specs}"
        " --increments {params.increments} --out {output.table} --figure {output.figure} > {log} 2>&1"


rule increment_benchmark:
    input:
        ifenn_specs=lambda w: [f"results/ifenn/{r}/spec.json" for r in config["increment_benchmark"]["runs"]],
        fem=lambda w: [f"results/fem/{config['ifenn_runs'][r]['fem_run']}/{f}" for r in config["increment_benchmark"]["runs"]
                       for f in ("fields.h5", "history.csv")],
        meshes=lambda w: sorted({f"results/mesh/{config['fem_runs'][config['ifenn_runs'][r]['fem_run']]['scene']}.xdmf"
                                 for r in config["increment_benchmark"]["runs"]}),
        model="results/picnn/model.pt",
    output:
        "results/benchmarks/increment_speed.csv",
    params:
        python=PYTHON,
        script=os.path.join(workflow.basedir, "benchmarks", "increment_speed.py"),
        increments=config.get("increment_benchmark", {}).get("increments", 40),
        solvers=lambda w: json.dumps(json.dumps({label: [name, config["solver"]["linear_solver_presets"][name]]
                                                 for label, name in config["increment_benchmark"]["solvers"].items()})),
        new_solver=config.get("increment_benchmark", {}).get("new_solver", ""),
        methods=" ".join(config.get("increment_benchmark", {}).get("methods", [])),
        zone=lambda w: json.dumps(json.dumps(config["ifenn"]["process_zone"])),
    # config benchmarks_alone: all cores, nothing else runs while it measures (it uses one)
    threads: benchmark_cores
    conda:
        "../envs/ifenn.yaml"
    log:
        "logs/benchmarks/increment_speed.log",
    benchmark:
        "benchmarks/speed/increment_speed.tsv"
    shell:
        "OMP_NUM_THREADS=1 {params.python} {params.script} --model {input.model} --specs {input.ifenn_specs}"
        " --solvers {params.solvers} --new-solver {params.new_solver} --process-zone {params.zone}"
        " --methods {params.methods} --increments {params.increments} --out {output} > {log} 2>&1"


rule reference_convergence:
    input:
        lambda w: sorted({f"{d}/history.csv" for case in reference_convergence_dirs().values()
                          for d in (case["fem_dir"], case["fine_dir"], *case["ifenn_dirs"].values())}),
    output:
        table=report("results/tables/reference_convergence.csv", caption="../report/reference_convergence.rst", category="Tables"),
        figure=report("results/figures/reference_convergence.png", caption="../report/reference_convergence.rst", category="IFENN runs"),
    params:
        cases=lambda w: reference_convergence_dirs(),
    conda:
        "../envs/ifenn.yaml"
    log:
        "logs/tables/reference_convergence.log",
    benchmark:
        "benchmarks/tables/reference_convergence.tsv"
    script:
        "../scripts/reference_convergence.py"


rule summary:
    """results/summary.md: the numbers docs/ quotes, rendered from this run's tables with the machine
    they ran on and the date (ifenn.studies.tables.summary)."""
    input:
        unpack(lambda w: SUMMARY_TABLES),
        machine="results/benchmarks/machine_speed.json",
    output:
        report("results/summary.md", caption="../report/summary.rst", category="Summary"),
    params:
        tables=SUMMARY_TABLES,
        config_files=[os.path.basename(f) for f in workflow.configfiles],
    conda:
        "../envs/ifenn.yaml"
    log:
        "logs/tables/summary.log",
    benchmark:
        "benchmarks/tables/summary.tsv"
    script:
        "../scripts/summary.py"
