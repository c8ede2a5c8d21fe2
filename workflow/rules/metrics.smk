# Accuracy and timing tables: every IFENN run against the FEM run it continues.


rule accuracy_table:
    input:
        ifenn=expand("results/ifenn/{run}/fields.h5", run=config["ifenn_runs"]),
        fem=lambda w: sorted({f"results/fem/{r['fem_run']}/fields.h5" for r in config["ifenn_runs"].values()}),
    output:
        report("results/tables/accuracy.csv", caption="../report/accuracy.rst", category="Tables"),
    params:
        runs={name: run["fem_run"] for name, run in config["ifenn_runs"].items()},
        material=config["material"],
    conda:
        "../envs/ifenn.yaml"
    log:
        "logs/tables/accuracy.log",
    script:
        "../scripts/accuracy_table.py"


rule timing_table:
    input:
        ifenn=expand("results/ifenn/{run}/history.csv", run=config["ifenn_runs"]),
        fem=lambda w: sorted({f"results/fem/{r['fem_run']}/history.csv" for r in config["ifenn_runs"].values()}),
    output:
        report("results/tables/timing.csv", caption="../report/timing.rst", category="Tables"),
    params:
        runs={name: run["fem_run"] for name, run in config["ifenn_runs"].items()},
    conda:
        "../envs/ifenn.yaml"
    log:
        "logs/tables/timing.log",
    script:
        "../scripts/timing_table.py"
