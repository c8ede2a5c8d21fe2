# The PICNN: training data from one FEM run, training with the physics loss, figures.


rule training_data:
    input:
        fields=lambda w: f"results/fem/{config['picnn']['training_run']}/fields.h5",
    output:
        "results/training/data.h5",
    params:
        increments=lambda w: config["picnn"]["training_increments"],
    priority: 100  # on the critical path: every IFENN run waits for the network
    conda:
        "../envs/ifenn.yaml"
    log:
        "logs/training/data.log",
    benchmark:
        "benchmarks/training/data.tsv"
    script:
        "../scripts/training_data.py"


rule train_picnn:
    input:
        data="results/training/data.h5",
    output:
        model="results/picnn/model.pt",
        loss="results/picnn/loss.csv",
        scores="results/picnn/scores.csv",
        provenance="results/picnn/provenance.json",
    params:
        spec=lambda w: json.dumps(training_spec(config), sort_keys=True),
    threads: lambda w: config["picnn"]["threads"]
    priority: 100  # on the critical path: every IFENN run waits for the network
    resources:
        mem_mb=4000,
        runtime=120,
    conda:
        "../envs/ifenn.yaml"
    log:
        "logs/training/train.log",
    benchmark:
        "benchmarks/training/train.tsv"
    script:
        "../scripts/train_picnn.py"


use rule train_picnn as train_picnn_preset with:
    # Optional (not in `all`): the paper's own settings, full images, hours on a CPU.
    #   snakemake results/picnn/presets/text/scores.csv     (lr 1e-4, 10,000 epochs)
    #   snakemake results/picnn/presets/released/scores.csv (lr 1e-3, 5,000 epochs)
    output:
        model="results/picnn/presets/{preset}/model.pt",
        loss="results/picnn/presets/{preset}/loss.csv",
        scores="results/picnn/presets/{preset}/scores.csv",
        provenance="results/picnn/presets/{preset}/provenance.json",
    wildcard_constraints:
        preset="released|text",
    params:
        spec=lambda w: json.dumps({**training_spec(config), "preset": w.preset, "settings": {}}, sort_keys=True),
    log:
        "logs/training/train_{preset}.log",
    benchmark:
        "benchmarks/training/train_{preset}.tsv"
    resources:
        mem_mb=4000,
        runtime=600,


rule training_data_figure:
    input:
        "results/training/data.h5",
    output:
        report("results/figures/training/training_data.png", caption="../report/training_data.rst", category="PICNN training"),
    conda:
        "../envs/ifenn.yaml"
    log:
        "logs/figures/training_data.log",
    benchmark:
        "benchmarks/figures/training_data.tsv"
    script:
        "../scripts/training_data_figure.py"


rule training_figure:
    input:
        data="results/training/data.h5",
        model="results/picnn/model.pt",
        loss="results/picnn/loss.csv",
    output:
        report("results/figures/training/training.png", caption="../report/training.rst", category="PICNN training"),
    conda:
        "../envs/ifenn.yaml"
    log:
        "logs/figures/training.log",
    benchmark:
        "benchmarks/figures/training.tsv"
    script:
        "../scripts/training_figure.py"
