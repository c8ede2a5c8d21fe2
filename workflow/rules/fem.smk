# Plain-FEM phase-field reference runs (staggered, dolfinx).


rule fem_spec:
    # The resolved, self-contained description of one run; it changes (and reruns the run)
    # only when a config value the run depends on changes.
    output:
        "results/fem/{run}/spec.json",
    params:
        spec=lambda w: run_spec_json("fem", w.run),
    priority: 100  # instant; unlocks its FEM run (mesh.smk)
    log:
        "logs/fem/{run}_spec.log",
    benchmark:
        "benchmarks/specs/fem_{run}.tsv"
    conda:
        "../envs/ifenn.yaml"
    script:
        "../scripts/write_spec.py"


rule fem:
    wildcard_constraints:
        run=run_pattern(PAIRED_RUNS),  # the whole-run benchmark's FEM runs: rule whole_run_pair
    input:
        unpack(lambda w: start_inputs("fem", w.run)),  # a run whose first increments another run computed (common.smk run_start)
        spec="results/fem/{run}/spec.json",
        mesh=lambda w: f"results/mesh/{config['fem_runs'][w.run]['scene']}.xdmf",
    output:
        history="results/fem/{run}/history.csv",
        fields="results/fem/{run}/fields.h5",
        xdmf="results/fem/{run}/paraview.xdmf",
        xdmf_h5="results/fem/{run}/paraview.h5",
        provenance="results/fem/{run}/provenance.json",
    params:
        launcher=fem_launcher,
        python=PYTHON,
        out=lambda w, output: os.path.dirname(output.history),
        start=start_argument("fem"),
    threads: 1
    # the FEM runs are the long jobs and everything else waits on them: the training run first,
    # then longest first, before the short jobs whenever a core is free (common.smk fem_priority)
    priority: fem_priority
    resources:
        # on SLURM: `tasks` -> --ntasks; a non-empty `mpi` marks an MPI job, whose shell command
        # runs as the batch step (the launcher's mpirun starts the ranks in the allocation)
        mpi=lambda w: "mpirun" if fem_ranks(w) > 1 else "",
        tasks=fem_ranks,
        mem_mb=4000,
        runtime=240,
    conda:
        "../envs/ifenn.yaml"
    log:
        "logs/fem/{run}.log",
    benchmark:
        "benchmarks/fem/{run}.tsv"
    shell:
        "OMP_NUM_THREADS=1 {params.launcher} {params.python} -m ifenn fem --spec {input.spec} --mesh {input.mesh}"
        " --out {params.out} {params.start} > {log} 2>&1"


rule fem_force_figure:
    input:
        history="results/fem/{run}/history.csv",
    output:
        report("results/figures/fem/{run}_force_displacement.png", caption="../report/fem_force.rst", category="FEM reference runs"),
    params:
        force_unit=lambda w: "N" if "thickness" in config["scenes"][config["fem_runs"][w.run]["scene"]] else "N/mm",
    conda:
        "../envs/ifenn.yaml"
    log:
        "logs/figures/fem_{run}.log",
    benchmark:
        "benchmarks/figures/fem_{run}.tsv"
    script:
        "../scripts/fem_force_figure.py"
