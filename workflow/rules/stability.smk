# Stability where the methods fail: a sweep of FEM and IFENN cells on a small
# scene (config 'stability'), each classified automatically; see ifenn.studies.drivers.stability.


rule stability_cell_spec:
    output:
        "results/stability/{cell}/spec.json",
    params:
        spec=lambda w: json.dumps(STABILITY_CELLS[w.cell]["spec"], sort_keys=True),
    priority: 100  # instant; unlocks its run, whose own priority counts only once it is ready (fem.smk)
    wildcard_constraints:
        cell="(fem|ifenn)_[A-Za-z0-9_.+-]+",
    log:
        "logs/stability/{cell}_spec.log",
    benchmark:
        "benchmarks/specs/stability_{cell}.tsv"
    conda:
        "../envs/ifenn.yaml"
    script:
        "../scripts/write_spec.py"


rule stability_cell:
    input:
        unpack(stability_cell_inputs),
    output:
        "results/stability/{cell}/status.json",
    params:
        python=PYTHON,
        device=config["device"],  # where the network runs (ifenn.device)
        fem=lambda w, input: f"--fem-dir {os.path.dirname(input.fem_status)}" if "fem_status" in input.keys() else "",
        model=lambda w, input: f"--model {input.model}" if "model" in input.keys() else "",
        out=lambda w, output: os.path.dirname(output[0]),
    wildcard_constraints:
        cell="(fem|ifenn)_[A-Za-z0-9_.+-]+",
    threads: 1
    resources:
        mem_mb=2000,
        runtime=30,
    conda:
        "../envs/ifenn.yaml"
    log:
        "logs/stability/{cell}.log",
    benchmark:
        "benchmarks/stability/{cell}.tsv"
    shell:
        "OMP_NUM_THREADS=1 {params.python} -m ifenn cell --spec {input.spec} --device {params.device} --out {params.out}"
        " {params.fem} {params.model} > {log} 2>&1"


rule stability_table:
    input:
        expand("results/stability/{cell}/status.json", cell=STABILITY_CELLS),
    output:
        report("results/tables/stability.csv", caption="../report/stability.rst", category="Stability"),
    params:
        cell_root=lambda w, input: os.path.dirname(os.path.dirname(input[0])),  # results/stability/CELL/status.json
    conda:
        "../envs/ifenn.yaml"
    log:
        "logs/tables/stability.log",
    benchmark:
        "benchmarks/tables/stability.tsv"
    script:
        "../scripts/stability_table.py"


rule stability_figure:
    input:
        "results/tables/stability.csv",
    output:
        report("results/figures/stability_map.png", caption="../report/stability.rst", category="Stability"),
    conda:
        "../envs/ifenn.yaml"
    log:
        "logs/figures/stability_map.log",
    benchmark:
        "benchmarks/figures/stability_map.tsv"
    script:
        "../scripts/stability_figure.py"
