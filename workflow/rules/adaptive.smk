# Displacement meshes that follow the crack (ifenn.adaptive): runs on the adaptive mesh, and the
# table and figures that hold them against the finer uniform FEM (config adaptive_resolution).


rule adaptive_spec:
    output:
        "results/adaptive/{run}/spec.json",
    params:
        spec=lambda w: run_spec_json("adaptive", w.run),
    priority: 100  # instant; unlocks its run, whose own priority counts only once it is ready (fem.smk)
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
        unpack(adaptive_inputs),
    output:
        history="results/adaptive/{run}/history.csv",
        fields="results/adaptive/{run}/fields.h5",
        provenance="results/adaptive/{run}/provenance.json",
    params:
        python=PYTHON,
        device=config["device"],  # where the network runs (ifenn.device)
        model=lambda w, input: f"--model {input.model}" if "model" in input.keys() else "",
        out=lambda w, output: os.path.dirname(output.history),
        start=start_argument("adaptive"),
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
        "OMP_NUM_THREADS=1 {params.python} -m ifenn adaptive --spec {input.spec} {params.model} --device {params.device} --out {params.out} {params.start} > {log} 2>&1"


rule adaptive_resolution:
    input:
        adaptive_resolution_inputs,
    output:
        table=report("results/tables/adaptive_resolution.csv", caption="../report/adaptive_resolution.rst", category="Tables"),
        figure=report("results/figures/adaptive_resolution.png", caption="../report/adaptive_resolution.rst", category="Adaptive meshes"),
        mesh=report("results/figures/adaptive_mesh.png", caption="../report/adaptive_resolution.rst", category="Adaptive meshes"),
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
