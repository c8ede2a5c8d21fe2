"""Adapter: training data -> ifenn.network.training.train_picnn -> model, loss log, score table."""
import json
import time

import pandas as pd

from ifenn.device import describe, resolve_device
from ifenn.io import log_to, provenance, write_csv, write_json
from ifenn.network.picnn import save_picnn
from ifenn.network.training import resolve_settings, score_picnn, train_picnn
from ifenn.network.training_data import read_training_data
from ifenn.pixels import PixelGrid, SlitCuts
from ifenn.run_files import spec_hash

snakemake = snakemake  # noqa: F821 (injected by Snakemake)
log_to(snakemake.log[0])
spec = json.loads(snakemake.params.spec)
data = read_training_data(snakemake.input.data)
settings = resolve_settings({"preset": spec["preset"], **spec["settings"]})
material = spec["material"]
device = resolve_device(snakemake.config.get("device", "auto"))
started = time.perf_counter()
grid = PixelGrid(float(data["x0"]), float(data["y0"]), float(data["h_px"]), int(data["nx_px"]), int(data["ny_px"]))
cuts = SlitCuts.for_scene(spec["scene"], grid, settings["laplacian_padding"])
model, loss = train_picnn(list(data["history"]), float(data["h_px"]), material["Gc"], material["lc"], settings,
                          seed=spec["seed"], threads=snakemake.threads, progress=True, cuts=cuts, device=device)
wall = time.perf_counter() - started
save_picnn(model, snakemake.output.model, float(data["h_px"]), material["Gc"], material["lc"], spec_hash(spec),
           extra={"settings": settings, "training_increments": data["increment"].tolist()})
scores = pd.DataFrame(score_picnn(model, list(data["history"]), list(data["phase_field_gp"])))
scores.insert(0, "increment", data["increment"])
scores.insert(1, "u", data["u"])
scores["training_wall_s"] = wall
write_csv(snakemake.output.loss, loss)
write_csv(snakemake.output.scores, scores)
write_json(snakemake.output.provenance, provenance(spec_hash(spec), wall, threads=snakemake.threads, settings=settings,
                                                     device=describe(device)))
