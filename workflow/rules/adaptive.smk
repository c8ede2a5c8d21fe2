# Displacement meshes that follow the crack (ifenn.adaptive): runs on the adaptive mesh, and the
# table and figures that hold them against the finer uniform FEM (config adaptive_resolution).


rule adaptive_spec:
    output:
        "results/adaptive/{run}/spec.json",
    params:
        spec=lambda w: json.dumps(adaptive_run_spec(config, w.run), sort_keys=True),
    log:
        "logs/adaptive/{run}_spec.log",
    benchmark:
        "benchmarks/specs/adaptive_{run}.tsv"
    conda:
        "../envs/ifenn.yaml"
    script:
        "../scripts/write_spec.py"


rule adaptive:
    input:
        spec="results/adaptive/{run}/spec.json",
    output:
        history="results/adaptive/{run}/history.csv",
        fields="results/adaptive/{run}/fields.h5",
        provenance="results/adaptive/{run}/provenance.json",
    params:
        python=PYTHON,
        out=lambda w, output: os.path.dirname(output.history),
    threads: 1
    resources:
        mem_mb=4000,
        runtime=240,
    conda:
        "../envs/ifenn.yaml"
    log:
        "logs/adaptive/{run}.log",
    benchmark:
        "benchmarks/adaptive/{run}.tsv"
    shell:
        "OMP_NUM_THREADS=1 {params.python} -m ifenn adaptive --spec {input.spec} --out {params.out} > {log} 2>&1"


def adaptive_resolution_cases():
    return {case: {"fem_run": e["fem_run"], "fine_fem_run": e["fine_fem_run"], "fem_dir": f"results/fem/{e['fem_run']}",
                   "fine_dir": f"results/fem/{e['fine_fem_run']}",
                   "adaptive_dirs": {run: f"results/adaptive/{run}" for run in e["adaptive_runs"]}}
            for case, e in config.get("adaptive_resolution", {}).items()}


def adaptive_resolution_inputs(wildcards):
    files = []
    for where in adaptive_resolution_cases().values():
        for folder in (where["fem_dir"], where["fine_dir"], *where["adaptive_dirs"].values()):
            files += [f"{folder}/history.csv", f"{folder}/provenance.json", f"{folder}/spec.json"]
        files += [f"{folder}/fields.h5" for folder in where["adaptive_dirs"].values()]
    return files


rule adaptive_resolution:
    input:
        adaptive_resolution_inputs,
    output:
        table="results/tables/adaptive_resolution.csv",
        figure="results/figures/adaptive_resolution.png",
        mesh="results/figures/adaptive_mesh.png",
    params:
        cases=adaptive_resolution_cases(),
    log:
        "logs/tables/adaptive_resolution.log",
    benchmark:
        "benchmarks/tables/adaptive_resolution.tsv"
    conda:
        "../envs/ifenn.yaml"
    script:
        "../scripts/adaptive_resolution.py"
