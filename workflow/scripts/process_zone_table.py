"""Adapter: process-zone and full-image IFENN run folders -> ifenn.studies.tables.metrics.process_zone_agreement, one row per pair."""
import pandas as pd

from ifenn.io import log_to, write_csv
from ifenn.studies.tables.metrics import process_zone_agreement

snakemake = snakemake  # noqa: F821 (injected by Snakemake)
log_to(snakemake.log[0])
rows = [{"run": zone, "full_run": where["full_run"], **process_zone_agreement(where["zone_dir"], where["full_dir"])}
        for zone, where in snakemake.params.pairs.items()]
write_csv(snakemake.output[0], pd.DataFrame(rows))
