"""Adapter: the whole-run benchmark's rows of each pair (rule whole_run_pair_*) -> one table each."""
from ifenn.io import log_to

snakemake = snakemake  # noqa: F821 (injected by Snakemake)
log_to(snakemake.log[0])

import pandas as pd  # noqa: E402

from ifenn.io import write_csv  # noqa: E402

write_csv(snakemake.output.summary, pd.concat([pd.read_csv(path) for path in snakemake.input.tables], ignore_index=True))
write_csv(snakemake.output.increments, pd.concat([pd.read_csv(path) for path in snakemake.input.increments], ignore_index=True))
