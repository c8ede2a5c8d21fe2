"""Adapter: the specimen's histories (forces of the whole specimen), the first run's phi and the
measured or published curve -> ifenn.studies.figures.specimen_figure and ifenn.studies.tables.specimens.specimen_table."""
import pandas as pd

from ifenn.io import atomic_path, log_to
from ifenn.run_files import read_phase_field_maps
from ifenn.studies.figures import specimen_figure
from ifenn.studies.tables.specimens import specimen_table

snakemake = snakemake  # noqa: F821 (injected by Snakemake)
log_to(snakemake.log[0])
params, inputs = snakemake.params, snakemake.input
labelled = ([(f"FEM {run}", path) for run, path in zip(params.runs, inputs.histories, strict=True)]
            + [(f"IFENN {run}", path) for run, path in zip(params.ifenn_runs, inputs.ifenn, strict=True)]
            + [(f"adaptive {run}", path) for run, path in zip(params.adaptive_runs, inputs.adaptive, strict=True)])
curves = {}
for (label, path), factor in zip(labelled, params.factors, strict=True):
    frame = pd.read_csv(path)
    frame["reaction_force"] *= factor
    curves[label if factor == 1 else f"{label} (x{factor})"] = frame
measured = pd.read_csv(inputs.measured, comment="#")
band = pd.read_csv(inputs.band[0], comment="#") if inputs.band else None
maps, attrs = read_phase_field_maps(inputs.fields)
specimen_figure(curves, measured, params.label, maps, attrs, params.scene, snakemake.output.figure,
                title=snakemake.wildcards.specimen, band=band, band_label=params.band_label)
with atomic_path(snakemake.output.table) as tmp:
    specimen_table(curves, measured, band).to_csv(tmp, index=False, float_format="%.9g")
