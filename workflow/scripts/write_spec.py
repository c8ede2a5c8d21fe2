"""Adapter: a run's resolved spec (params.spec, JSON text made when the DAG is built) -> spec.json.

A script, not a `run:` block: Snakemake runs a `run:` job in a new Snakemake process that reads
the whole workflow again (config validation, PETSc: ~4 s a job, most of the quick DAG's time with
a spec per run); a script starts a bare Python (~0.3 s)."""
import json

from ifenn.io import write_json

snakemake = snakemake  # noqa: F821 (injected by Snakemake)
write_json(snakemake.output[0], json.loads(snakemake.params.spec))
