# Structured Q1 meshes with slit notches (meshio XDMF + HDF5) and a picture of each scene.


rule mesh:
    output:
        xdmf="results/mesh/{scene}.xdmf",
        h5="results/mesh/{scene}.h5",
        meta="results/mesh/{scene}.json",
    params:
        scene=lambda w: config["scenes"][w.scene],
    # seconds each, and they unlock the FEM runs: a job's priority counts only once it is ready,
    # so the long FEM runs can start first only when their meshes and specs are already there
    priority: 100
    conda:
        "../envs/ifenn.yaml"
    log:
        "logs/mesh/{scene}.log",
    benchmark:
        "benchmarks/mesh/{scene}.tsv"
    script:
        "../scripts/mesh.py"


rule mesh_figure:
    input:
        xdmf="results/mesh/{scene}.xdmf",
    output:
        report("results/mesh/{scene}.png", caption="../report/mesh.rst", category="Scenes"),
    params:
        scene=lambda w: config["scenes"][w.scene],
    conda:
        "../envs/ifenn.yaml"
    log:
        "logs/mesh/{scene}_figure.log",
    benchmark:
        "benchmarks/mesh/{scene}_figure.tsv"
    script:
        "../scripts/mesh_figure.py"
