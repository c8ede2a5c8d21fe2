"""Adapter: one FEM/IFENN pair -> ifenn.plots.comparison_figure."""
import pandas as pd

from ifenn.plots import comparison_figure

snakemake = snakemake  # noqa: F821 (injected by Snakemake)
i, options = snakemake.input, snakemake.params.options
comparison_figure(pd.read_csv(i.fem_history), pd.read_csv(i.ifenn_history), i.fem_fields, i.ifenn_fields, snakemake.output[0],
                  title=f"{snakemake.wildcards.run}: FEM vs IFENN", levels=options.get("levels", 4), zoom=options.get("zoom"))
