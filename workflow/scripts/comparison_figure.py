"""Adapter: one FEM/IFENN pair -> ifenn.studies.figures.comparison_figure."""
import pandas as pd

from ifenn.io import log_to
from ifenn.studies.figures import comparison_figure

snakemake = snakemake  # noqa: F821 (injected by Snakemake)
log_to(snakemake.log[0])
i, options = snakemake.input, snakemake.params.options
verified = "verified_history" in i.keys()
comparison_figure(pd.read_csv(i.fem_history), pd.read_csv(i.ifenn_history), i.fem_fields, i.ifenn_fields, snakemake.output[0],
                  title=f"{snakemake.wildcards.run}: FEM vs IFENN" + (" (published and verified)" if verified else ""),
                  levels=options.get("levels", 4), zoom=options.get("zoom"),
                  verified_history=pd.read_csv(i.verified_history) if verified else None,
                  verified_fields=i.verified_fields if verified else None)
