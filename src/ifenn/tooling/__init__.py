"""The workflow's own bookkeeping: what a Snakemake run spent, by stage and job (``stage_times``)."""
