"""Adapter: whole-path IFENN and FEM run folders -> ifenn.studies.drivers.whole_path tables and figure."""
from ifenn.io import log_to

snakemake = snakemake  # noqa: F821 (injected by Snakemake)
log_to(snakemake.log[0])

import pandas as pd  # noqa: E402

from ifenn.io import write_csv  # noqa: E402
from ifenn.run_files import read_history, read_spec  # noqa: E402
from ifenn.studies.drivers.whole_path import network_before_nucleation, whole_path_table  # noqa: E402
from ifenn.studies.figures import whole_path_figure  # noqa: E402

runs = snakemake.params.runs
table = whole_path_table(runs, snakemake.params.targets)
write_csv(snakemake.output.table, table)
frames = []
for run, case in snakemake.params.network_cases.items():
    frames.append(network_before_nucleation(read_spec(case["spec"]), case["fem_fields"], case["model"], pd.read_csv(case["history"]),
                                            device=snakemake.params.device)
                  .assign(run=run, fem_run=runs[run]["fem_run"]))
network = pd.concat(frames, ignore_index=True) if frames else pd.DataFrame(columns=["run", "fem_run", "increment"])
write_csv(snakemake.output.network, network[["run", "fem_run", *[c for c in network.columns if c not in ("run", "fem_run")]]])
pairs = {run: (read_history(where["fem_dir"]), read_history(where["ifenn_dir"])) for run, where in runs.items()}
whole_path_figure(pairs, table, snakemake.output.figure)
