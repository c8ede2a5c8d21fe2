# The paper's comparison figures, from the FEM and IFENN runs (config 'figures').


rule comparison_figure:
    input:
        unpack(lambda w: comparison_inputs(w.run)),
    output:
        report("results/figures/paper/{run}_comparison.png", caption="../report/comparison.rst", category="Paper figures"),
    params:
        options=lambda w: config["figures"]["comparisons"][w.run],
    conda:
        "../envs/ifenn.yaml"
    log:
        "logs/figures/comparison_{run}.log",
    benchmark:
        "benchmarks/figures/comparison_{run}.tsv"
    script:
        "../scripts/comparison_figure.py"


rule views_3d_figure:
    input:
        unpack(lambda w: ifenn_pair(config["figures"]["views_3d"]["run"])),
    output:
        report("results/figures/paper/views_3d.png", caption="../report/views_3d.rst", category="Paper figures"),
    params:
        options=config["figures"]["views_3d"],
    conda:
        "../envs/ifenn.yaml"
    log:
        "logs/figures/views_3d.log",
    benchmark:
        "benchmarks/figures/views_3d.tsv"
    script:
        "../scripts/views_3d_figure.py"


rule mesh_study_figure:
    input:
        pairs=lambda w: [path for run in config["figures"]["mesh_study"]["runs"] for path in ifenn_pair(run).values()],
    output:
        report("results/figures/paper/mesh_study.png", caption="../report/mesh_study.rst", category="Paper figures"),
    params:
        options=config["figures"]["mesh_study"],
        pairs={run: ifenn_pair(run) for run in config["figures"]["mesh_study"]["runs"]},
    conda:
        "../envs/ifenn.yaml"
    log:
        "logs/figures/mesh_study.log",
    benchmark:
        "benchmarks/figures/mesh_study.tsv"
    script:
        "../scripts/mesh_study_figure.py"


rule phase_field_time_figure:
    input:
        timing="results/tables/timing.csv",
    output:
        report("results/figures/paper/phase_field_time.png", caption="../report/phase_field_time.rst", category="Paper figures"),
    params:
        cases=[{"run": run, "lc_over_h": lc_over_h(config["ifenn_runs"][run]["fem_run"])}
               for run in config["figures"]["mesh_study"]["runs"]],
    conda:
        "../envs/ifenn.yaml"
    log:
        "logs/figures/phase_field_time.log",
    benchmark:
        "benchmarks/figures/phase_field_time.tsv"
    script:
        "../scripts/phase_field_time_figure.py"


rule specimen_figure:
    """A specimen of the field against its measured or published curve (config specimens): the
    figure, and the table of each run's peak, u at the peak and work of the load against the curve's."""
    input:
        histories=lambda w: [f"results/fem/{run}/history.csv" for run in config["specimens"][w.specimen]["fem_runs"]],
        ifenn=lambda w: [f"results/ifenn/{run}/history.csv" for run in config["specimens"][w.specimen].get("ifenn_runs", [])],
        adaptive=lambda w: [f"results/adaptive/{run}/history.csv" for run in config["specimens"][w.specimen].get("adaptive_runs", [])],
        fields=lambda w: f"results/fem/{config['specimens'][w.specimen]['fem_runs'][0]}/fields.h5",
        measured=lambda w: os.path.join(workflow.basedir, config["specimens"][w.specimen]["measured"]["file"]),
        band=lambda w: [os.path.join(workflow.basedir, config["specimens"][w.specimen]["band"]["file"])]
                       if "band" in config["specimens"][w.specimen] else [],
    output:
        figure=report("results/figures/specimens/{specimen}.png", caption="../report/specimen.rst", category="The field's specimens"),
        table="results/tables/specimens/{specimen}.csv",
    params:
        runs=lambda w: config["specimens"][w.specimen]["fem_runs"],
        ifenn_runs=lambda w: config["specimens"][w.specimen].get("ifenn_runs", []),
        adaptive_runs=lambda w: config["specimens"][w.specimen].get("adaptive_runs", []),
        label=lambda w: config["specimens"][w.specimen]["measured"]["label"],
        band_label=lambda w: config["specimens"][w.specimen].get("band", {}).get("label", ""),
        factors=lambda w: specimen_factors(w.specimen),
        scene=lambda w: config["scenes"][config["fem_runs"][config["specimens"][w.specimen]["fem_runs"][0]]["scene"]],
    conda:
        "../envs/ifenn.yaml"
    log:
        "logs/figures/specimen_{specimen}.log",
    benchmark:
        "benchmarks/figures/specimen_{specimen}.tsv"
    script:
        "../scripts/specimen_figure.py"
