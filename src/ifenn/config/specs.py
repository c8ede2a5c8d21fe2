"""The config's runs resolved into self-contained specs (JSON-serialisable): what one FEM, IFENN,
adaptive or training job needs, with the switch-over, the finer references and the load values
they are built from."""

from __future__ import annotations

from ifenn.config.loading import ConfigError, deep_merge
from ifenn.materials import scene_material
from ifenn.specs import spec_dict, typed_spec


def whole(kind: str, spec: dict) -> dict:
    """``spec`` read into its type (:mod:`ifenn.specs`: an unknown key is refused) and written back
    whole, every default explicit, so that spec.json and its hash say everything the run used."""
    return spec_dict(typed_spec(kind, spec))

SWITCH_OVER = ("phi_threshold", "increment", "start")


def schedule_increments(schedule: list[dict] | dict) -> int | None:
    """Number of increments of a fixed schedule; None for an adaptive one."""
    return None if isinstance(schedule, dict) else sum(seg["increments"] for seg in schedule)


def load_values(schedule: list[dict]) -> list[float]:
    """Prescribed displacement (mm) after each increment of a schedule, increments 1..N."""
    values, u = [], 0.0
    for segment in schedule:
        for _ in range(segment["increments"]):
            u += segment["step"]
            values.append(round(u, 15))
    return values


def switch_over(config: dict, run: str) -> tuple[str, int | None]:
    """(criterion, switch increment) of an IFENN run: its entry's ``switch_over`` /
    ``switch_increment``, else the 'ifenn' section's (criteria in SWITCH_OVER)."""
    entry = config["ifenn_runs"][run]
    return (entry.get("switch_over", config["ifenn"].get("switch_over", "phi_threshold")),
            entry.get("switch_increment", config["ifenn"].get("switch_increment")))


def paired_runs(config: dict) -> dict[str, str]:
    """FEM run -> whole-path IFENN run, for the runs of 'whole_run_benchmark': the workflow computes
    each pair in one process, increments interleaved, and the benchmark reads their histories
    (:func:`ifenn.studies.drivers.whole_run_benchmark.paired_whole_run`); {} without the section."""
    return {config["ifenn_runs"][run]["fem_run"]: run for run in (config.get("whole_run_benchmark") or {}).get("runs", [])}


def finer_reference_runs(config: dict) -> dict[str, str]:
    """Each finer reference of reference_convergence and adaptive_resolution (``fine_fem_run``)
    -> the run that computes it: itself (``finer_references: uniform``) or its adaptive run
    '<fine_fem_run>-adaptive' (``adaptive``: the same scene and schedule on the adaptive mesh,
    with ``finer_reference_mesh``'s settings: by default phi on that scene's pixels, h/4 for the
    -fine scenes, and the finest displacement cells two pixels wide, h/2)."""
    fines = [entry["fine_fem_run"] for section in ("reference_convergence", "adaptive_resolution")
             for entry in config.get(section, {}).values()]
    adaptive = config.get("finer_references", "uniform") == "adaptive"
    return {fine: f"{fine}-adaptive" if adaptive else fine for fine in fines}


def speed_accuracy_setups(config: dict) -> dict:
    """config 'speed_accuracy' with each finer reference in a ``fem`` list replaced by the run that
    computes it (:func:`finer_reference_runs`): under ``finer_references: adaptive`` it moves to the
    ``adaptive`` list as '<fine_fem_run>-adaptive', so the chart shows the reference that `all` runs
    (and `all` need not run the uniform one for the chart alone)."""
    replaced = {fine: run for fine, run in finer_reference_runs(config).items() if run != fine}
    setups = {}
    for scene, setup in config.get("speed_accuracy", {}).items():
        setup = dict(setup)
        fem = list(setup.get("fem", []))
        moved = [replaced[run] for run in fem if run in replaced]
        if moved:
            setup["fem"] = [run for run in fem if run not in replaced]
            setup["adaptive"] = list(setup.get("adaptive", [])) + [run for run in moved if run not in setup.get("adaptive", [])]
        setups[scene] = setup
    return setups


def finer_reference_dir(config: dict, fine_fem_run: str) -> str:
    """Where the finer reference named ``fine_fem_run`` lives (:func:`finer_reference_runs`)."""
    name = finer_reference_runs(config).get(fine_fem_run, fine_fem_run)
    return f"results/adaptive/{name}" if name != fine_fem_run else f"results/fem/{fine_fem_run}"


def training_spec(config: dict) -> dict:
    """What the training rules need: the PICNN section, material and the training run's scene
    (its slits cut the loss's stencil, as in every pixel operator)."""
    scene = config["scenes"][config["fem_runs"][config["picnn"]["training_run"]]["scene"]]
    return whole("training", {**config["picnn"], "material": scene_material(config["material"], scene), "scene": scene})


def fem_run_spec(config: dict, run: str) -> dict:
    """Everything one FEM run needs, resolved and self-contained (JSON-serialisable)."""
    if run not in config["fem_runs"]:
        raise ConfigError(f"unknown FEM run '{run}'; allowed: {sorted(config['fem_runs'])}")
    entry = config["fem_runs"][run]
    solver = config["solver"]
    preset = entry.get("linear_solvers", solver["linear_solvers"])
    schedule = config["schedules"][entry["schedule"]]
    n_inc = schedule_increments(schedule)
    save = set(entry.get("save_fields", []))
    if n_inc is not None:
        save |= set(range(solver["save_every"], n_inc + 1, solver["save_every"]))
    if run == config["picnn"]["training_run"]:
        save |= set(config["picnn"]["training_increments"])
    views = config.get("figures", {}).get("views_3d")
    if views and config.get("ifenn_runs", {}).get(views["run"], {}).get("fem_run") == run:
        save.add(views["increment"])
    # the state an IFENN run switches over from at a given increment
    for name, other in config.get("ifenn_runs", {}).items():
        criterion, increment = switch_over(config, name)
        if other["fem_run"] == run and criterion == "increment" and increment is not None:
            save.add(increment)
    # fixed schedules: every load value (and the saved increments) in the spec; adaptive
    # ones: the controller's settings, and fields saved every save_every increments
    loads = {"load": load_values(schedule)} if n_inc is not None else {"adaptive": schedule["adaptive"], "save_every": solver["save_every"]}
    return whole("fem", {
        "name": run,
        "scene_name": entry["scene"],
        "scene": config["scenes"][entry["scene"]],
        "material": scene_material(config["material"], config["scenes"][entry["scene"]]),
        "schedule_name": entry["schedule"],
        **loads,
        "stagger_max_iterations": entry.get("stagger_max_iterations", solver["stagger_max_iterations"]),
        "stagger_tolerance": entry.get("stagger_tolerance", solver["stagger_tolerance"]),
        "linear_solvers": preset,
        "petsc": solver["linear_solver_presets"][preset],
        "checkpoint_every": solver["checkpoint_every"],
        "save_fields": sorted(save),
        "switch_phi_max": config["ifenn"]["switch_phi_max"],
        "mpi_ranks": entry.get("mpi_ranks", 1),
    })


IFENN_OPTIONS = ("predictor", "evaluation", "history_cap", "smoothing_sigma", "smoothing_truncate", "irreversible", "pixel_padding")


def ifenn_run_spec(config: dict, run: str) -> dict:
    """An IFENN run: the spec of its FEM run (scene, schedule, solvers, switch threshold)
    plus the hybrid options (config 'ifenn', overridden per run) and the switch-over criterion
    (``switch_over``, ``switch_increment``)."""
    if run not in config.get("ifenn_runs", {}):
        raise ConfigError(f"unknown IFENN run '{run}'; allowed: {sorted(config.get('ifenn_runs', {}))}")
    entry = config["ifenn_runs"][run]
    spec = fem_run_spec(config, entry["fem_run"])
    spec.update(name=run, fem_run=entry["fem_run"], save_fields=spec["save_fields"])
    for key in IFENN_OPTIONS:
        spec[key] = entry.get(key, config["ifenn"][key])
    spec["inference"] = entry.get("inference", config["ifenn"]["inference"])
    if spec["inference"] == "process_zone":  # its settings belong to the spec only when used
        spec["process_zone"] = deep_merge(config["ifenn"]["process_zone"], entry.get("process_zone", {}))
    verification = deep_merge(config["ifenn"]["verification"], entry.get("verification", {}))
    if verification["enabled"]:  # its settings belong to the spec only when used
        spec["verification"] = verification
    for key in ("stagger_max_iterations", "stagger_tolerance"):
        spec[key] = entry.get(key, spec[key])
    criterion, increment = switch_over(config, run)
    spec.update(switch_over=criterion, switch_increment=increment if criterion == "increment" else None)
    return whole("ifenn", spec)


#: what an adaptive run may set for itself instead of taking it from its FEM run
ADAPTIVE_RUN_OVERRIDES = ("scene", "schedule", "stagger_max_iterations")


def adaptive_run_spec(config: dict, run: str) -> dict:
    """An adaptive-mesh run: its FEM run's spec (scene, schedule, solvers; the entry may name its own
    ``scene``, the same specimen on more elements, ``schedule`` and ``stagger_max_iterations``:
    ADAPTIVE_RUN_OVERRIDES, so that a variant needs no FEM run of its own on the uniform mesh), the merged
    ``adaptive_mesh`` settings (:class:`ifenn.adaptive.run.MeshSettings`) and, for a verified
    IFENN run (``ifenn_run``), that run's hybrid settings."""
    if run not in config.get("adaptive_runs", {}):
        raise ConfigError(f"unknown adaptive run '{run}'; allowed: {sorted(config.get('adaptive_runs', {}))}")
    entry = config["adaptive_runs"][run]
    # the FEM run's entry with the adaptive run's own scene, schedule or staggering, resolved as FEM's
    fem = {**config["fem_runs"][entry["fem_run"]], **{k: entry[k] for k in ADAPTIVE_RUN_OVERRIDES if k in entry}}
    spec = fem_run_spec({**config, "fem_runs": {**config["fem_runs"], entry["fem_run"]: fem}}, entry["fem_run"])
    if entry.get("ifenn_run"):   # the verified IFENN step's settings (predictor, verification, ...)
        hybrid = ifenn_run_spec(config, entry["ifenn_run"])
        fem_keys = fem_run_spec(config, config["ifenn_runs"][entry["ifenn_run"]]["fem_run"])   # not the IFENN run's loads
        spec.update({k: v for k, v in hybrid.items() if k not in spec and k not in fem_keys and k not in ("switch_over", "switch_increment")},
                    ifenn_run=entry["ifenn_run"])
    settings = {**config["adaptive_mesh"], **entry.get("adaptive_mesh", {})}
    spec.update(name=run, fem_run=entry["fem_run"], adaptive_mesh=settings)
    if settings.get("linear_solvers"):   # the displacement solve's preset on the adaptive mesh
        preset = config["solver"]["linear_solver_presets"][settings["linear_solvers"]]
        # every displacement key from that preset (options, kept preconditioner, matrix storage), none from the FEM run's
        petsc = {k: v for k, v in spec["petsc"].items() if not k.startswith("displacement")}
        spec.update(linear_solvers=settings["linear_solvers"], petsc={**petsc, **{k: v for k, v in preset.items() if k.startswith("displacement")}})
    return whole("adaptive", spec)
