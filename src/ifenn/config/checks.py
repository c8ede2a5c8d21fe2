"""The config's checks across keys (the schema checks each key alone): every problem named with its
key, its value and what is allowed, before any job starts. Checks of one scene's geometry and
material live beside them (:func:`ifenn.geometry.scene_problems`, :func:`ifenn.materials.material_problems`,
:func:`ifenn.fem.supports.problems`); a PETSc option's names, :mod:`ifenn.config.petsc_names`.
"""

from __future__ import annotations

import math

import jsonschema

from ifenn import geometry, materials
from ifenn.config.loading import deep_merge
from ifenn.config.petsc_names import petsc_problems
from ifenn.config.specs import SWITCH_OVER, schedule_increments, switch_over
from ifenn.fem import supports
from ifenn.materials import lc_over_h, scene_material
from ifenn.network.settings import resolve_settings
from ifenn.schema import REPO

#: speed_accuracy: method -> the config section of its runs
SPEED_ACCURACY_METHODS = {"fem": "fem_runs", "ifenn": "ifenn_runs", "adaptive": "adaptive_runs"}


def semantic_problems(config: dict, schema: dict, petsc_names: bool = True) -> list[str]:
    """Every problem across keys of a config the schema accepted (defaults filled)."""
    return (_device_problems(config) + _solver_problems(config, petsc_names) + _scene_problems(config)
            + _schedule_and_fem_run_problems(config) + _picnn_problems(config) + _figure_problems(config)
            + _speed_accuracy_problems(config) + _study_problems(config) + _switch_over_problems(config)
            + _specimen_problems(config) + _reference_convergence_problems(config) + _ifenn_run_problems(config)
            + _adaptive_problems(config, schema))


def _device_problems(config: dict) -> list[str]:
    if config.get("device") != "cuda":   # torch is imported only for this (ifenn.device)
        return []
    from ifenn.device import resolve_device

    try:
        resolve_device("cuda")
    except ValueError as error:
        return [str(error)]
    return []


def _solver_problems(config: dict, petsc_names: bool) -> list[str]:
    problems: list[str] = []
    presets = config["solver"]["linear_solver_presets"]
    if config["solver"]["linear_solvers"] not in presets:
        problems.append(
            f"config key 'solver.linear_solvers': '{config['solver']['linear_solvers']}' "
            f"is not a preset; allowed: {sorted(presets)}"
        )
    for name, preset in presets.items():
        if "displacement_reuse" in preset and preset["displacement"].get("ksp_type", "gmres") == "preonly":
            problems.append(f"config key 'solver.linear_solver_presets.{name}.displacement_reuse': a kept preconditioner "
                            "needs a Krylov solve (ksp_type cg, ...), got ksp_type 'preonly'")
    for name, preset in presets.items():
        for field in ("displacement", "phase_field"):
            if petsc_names:
                problems += petsc_problems(f"solver.linear_solver_presets.{name}.{field}", preset[field])
    return problems


def _scene_problems(config: dict) -> list[str]:
    """Each scene's geometry, supports and material (the checks beside each)."""
    problems = []
    for name, scene in config["scenes"].items():
        key = f"scenes.{name}"
        problems += geometry.scene_problems(scene, key)
        if geometry.domain_is_valid(scene):
            problems += supports.problems(scene, key)
            problems += materials.material_problems(config["material"], scene, name)
    return problems


def _schedule_and_fem_run_problems(config: dict) -> list[str]:
    problems = []
    presets = config["solver"]["linear_solver_presets"]
    for name, schedule in config["schedules"].items():
        adaptive = schedule.get("adaptive") if isinstance(schedule, dict) else None
        if adaptive and not adaptive["step_min"] <= adaptive["step_initial"] <= adaptive["step_max"] <= adaptive["u_end"]:
            problems.append(f"config key 'schedules.{name}.adaptive': need step_min <= step_initial <= step_max <= u_end, "
                            f"got {adaptive}")
    for name, run in config["fem_runs"].items():
        key = f"fem_runs.{name}"
        if run["scene"] not in config["scenes"]:
            problems.append(f"config key '{key}.scene': '{run['scene']}' is not a scene; allowed: {sorted(config['scenes'])}")
        if run["schedule"] not in config["schedules"]:
            problems.append(
                f"config key '{key}.schedule': '{run['schedule']}' is not a schedule; allowed: {sorted(config['schedules'])}"
            )
            continue
        if "linear_solvers" in run and run["linear_solvers"] not in presets:
            problems.append(f"config key '{key}.linear_solvers': '{run['linear_solvers']}' is not a preset; allowed: {sorted(presets)}")
        n_inc = schedule_increments(config["schedules"][run["schedule"]])
        bad = [i for i in run.get("save_fields", []) if n_inc is not None and i > n_inc]
        if bad:
            problems.append(f"config key '{key}.save_fields': increments {bad} exceed the schedule's {n_inc} increments (allowed 1..{n_inc})")
    return problems


def _picnn_problems(config: dict) -> list[str]:
    problems = []
    picnn = config["picnn"]
    if picnn["training_run"] not in config["fem_runs"]:
        problems.append(f"config key 'picnn.training_run': '{picnn['training_run']}' is not a FEM run; allowed: {sorted(config['fem_runs'])}")
    else:
        run = config["fem_runs"][picnn["training_run"]]
        n_inc = schedule_increments(config["schedules"].get(run["schedule"], []))
        bad = [i for i in picnn["training_increments"] if n_inc is not None and i > n_inc]
        if bad:
            problems.append(f"config key 'picnn.training_increments': {bad} exceed the {n_inc} increments of run '{picnn['training_run']}' (allowed 1..{n_inc})")
    try:
        resolve_settings({"preset": picnn["preset"], **picnn["settings"]})
    except KeyError as error:
        problems.append(f"config key 'picnn.settings': {error}")
    return problems


def _figure_problems(config: dict) -> list[str]:
    problems = []
    figures = config["figures"]
    named = [(f"figures.comparisons.{r}", r) for r in figures["comparisons"]]
    named += [(f"figures.comparisons.{r}.verified", o["verified"]) for r, o in figures["comparisons"].items() if "verified" in o]
    named += [("figures.views_3d.run", figures["views_3d"]["run"])]
    named += [(f"figures.mesh_study.runs[{k}]", r) for k, r in enumerate(figures["mesh_study"]["runs"])]
    for key, run in named:
        if run not in config.get("ifenn_runs", {}):
            problems.append(f"config key '{key}': '{run}' is not an IFENN run; allowed: {sorted(config.get('ifenn_runs', {}))}")
    for run, options in figures["comparisons"].items():
        other = options.get("verified")
        runs = config.get("ifenn_runs", {})
        if other in runs and run in runs and runs[other]["fem_run"] != runs[run]["fem_run"]:
            problems.append(f"config key 'figures.comparisons.{run}.verified': '{other}' continues FEM run "
                            f"'{runs[other]['fem_run']}', not '{runs[run]['fem_run']}'")
    return problems


def _speed_accuracy_problems(config: dict) -> list[str]:
    problems = []
    for scene, setup in config.get("speed_accuracy", {}).items():
        method = setup.get("reference_method", "fem")
        if method not in SPEED_ACCURACY_METHODS:
            problems.append(f"config key 'speed_accuracy.{scene}.reference_method': '{method}'; allowed: {list(SPEED_ACCURACY_METHODS)}")
            method = "fem"
        elif setup["reference"] not in setup.get(method, []):
            problems.append(f"config key 'speed_accuracy.{scene}.reference': '{setup['reference']}' must be one of the "
                            f"scene's {method} runs (a point of the chart); listed: {setup.get(method, [])}")
        for key, pool in (("reference", SPEED_ACCURACY_METHODS[method]), *SPEED_ACCURACY_METHODS.items()):
            names = [setup[key]] if key == "reference" else setup.get(key, [])
            for run in names:
                if run not in config.get(pool, {}):
                    problems.append(f"config key 'speed_accuracy.{scene}.{key}': '{run}' is not in {pool}; allowed: {sorted(config.get(pool, {}))}")
        listed = [run for method in SPEED_ACCURACY_METHODS for run in setup.get(method, [])]
        if "baseline" in setup and setup["baseline"] not in setup.get("fem", []):
            problems.append(f"config key 'speed_accuracy.{scene}.baseline': '{setup['baseline']}' must be one of the scene's "
                            f"fem runs (the FEM run to beat); listed: {setup.get('fem', [])}")
        for k, run in enumerate(setup.get("combined", [])):
            if run not in listed:
                problems.append(f"config key 'speed_accuracy.{scene}.combined[{k}]': '{run}' is not a point of the scene's "
                                f"chart; allowed: {listed}")
    return problems


def _study_problems(config: dict) -> list[str]:
    """The runs the benchmarks and studies name (phase_field_benchmark, network_worth, error_sources,
    increment_benchmark) and the stability sweep's scene and steps."""
    problems = []
    presets = config["solver"]["linear_solver_presets"]
    for run in config.get("phase_field_benchmark", {}).get("runs", []):
        if run not in config.get("ifenn_runs", {}):
            problems.append(f"config key 'phase_field_benchmark.runs': '{run}' is not an IFENN run; allowed: {sorted(config.get('ifenn_runs', {}))}")
    for run in config.get("network_worth", {}).get("runs", []):
        entry = config.get("ifenn_runs", {}).get(run)
        if entry is None or not (entry.get("verification") or {}).get("enabled", False):
            verified = sorted(r for r, e in config.get("ifenn_runs", {}).items() if (e.get("verification") or {}).get("enabled", False))
            problems.append(f"config key 'network_worth.runs': '{run}' is not a verified IFENN run; allowed: {verified}")
    for run in config.get("error_sources", {}).get("runs", []):
        entry = config.get("ifenn_runs", {}).get(run)
        if entry is None:
            problems.append(f"config key 'error_sources.runs': '{run}' is not an IFENN run; allowed: {sorted(config.get('ifenn_runs', {}))}")
        elif entry.get("predictor", config["ifenn"]["predictor"]) != "picnn":
            problems.append(f"config key 'error_sources.runs': '{run}' does not use the PICNN (predictor "
                            f"'{entry.get('predictor', config['ifenn']['predictor'])}'): there is no network error to split off")
    bench = config.get("increment_benchmark")
    if bench:
        for run in bench["runs"]:
            if run not in config.get("ifenn_runs", {}):
                problems.append(f"config key 'increment_benchmark.runs': '{run}' is not an IFENN run; allowed: {sorted(config.get('ifenn_runs', {}))}")
            elif "ifenn-verified" in bench["methods"]:
                if not {**config["ifenn"]["verification"], **config["ifenn_runs"][run].get("verification", {})}["enabled"]:
                    problems.append(f"config key 'increment_benchmark.runs': '{run}' is not a verified IFENN run "
                                    "(verification.enabled), which method 'ifenn-verified' times")
        for label, preset in bench["solvers"].items():
            if preset not in presets:
                problems.append(f"config key 'increment_benchmark.solvers.{label}': '{preset}' is not a preset; allowed: {sorted(presets)}")
        missing = {"gamg", "direct", bench["new_solver"]} - set(bench["solvers"])
        if missing:
            problems.append(f"config key 'increment_benchmark.solvers': labels {sorted(missing)} are missing "
                            "(gamg: the baseline, direct: the force reference, and new_solver)")
    sweep = config.get("stability")
    if sweep:
        if sweep["scene"] not in config["scenes"]:
            problems.append(f"config key 'stability.scene': '{sweep['scene']}' is not a scene; allowed: {sorted(config['scenes'])}")
        bad = [s for s in [sweep["step"], *sweep["steps"]] if not 1 <= sweep["u_end"] / s <= 100000]
        if bad:
            problems.append(f"config key 'stability.steps': steps {bad} give outside 1..100000 increments to u_end = {sweep['u_end']}")
    return problems


def _specimen_problems(config: dict) -> list[str]:
    problems = []
    for name, specimen in config.get("specimens", {}).items():
        for run in specimen["fem_runs"]:
            if run not in config["fem_runs"]:
                problems.append(f"config key 'specimens.{name}.fem_runs': '{run}' is not a FEM run; allowed: {sorted(config['fem_runs'])}")
        for run in specimen.get("ifenn_runs", []):
            if run not in config.get("ifenn_runs", {}):
                problems.append(f"config key 'specimens.{name}.ifenn_runs': '{run}' is not an IFENN run; "
                                f"allowed: {sorted(config.get('ifenn_runs', {}))}")
        for run in specimen.get("adaptive_runs", []):
            if run not in config.get("adaptive_runs", {}):
                problems.append(f"config key 'specimens.{name}.adaptive_runs': '{run}' is not an adaptive run; "
                                f"allowed: {sorted(config.get('adaptive_runs', {}))}")
        for key in ("measured", "band"):
            if key in specimen and not (REPO / specimen[key]["file"]).is_file():
                problems.append(f"config key 'specimens.{name}.{key}.file': no file {specimen[key]['file']} in the repository")
    return problems


def _ifenn_run_problems(config: dict) -> list[str]:
    problems = []
    for name, run in config.get("ifenn_runs", {}).items():
        if run["fem_run"] not in config["fem_runs"]:
            problems.append(
                f"config key 'ifenn_runs.{name}.fem_run': '{run['fem_run']}' is not a FEM run; allowed: {sorted(config['fem_runs'])}"
            )
        setting = {key: run.get(key, config["ifenn"].get(key)) for key in ("inference", "predictor", "evaluation")}
        if setting["inference"] == "process_zone" and (setting["predictor"] != "picnn" or setting["evaluation"] != "orbit"):
            problems.append(f"config key 'ifenn_runs.{name}.inference': process_zone needs predictor 'picnn' with evaluation "
                            f"'orbit', got predictor '{setting['predictor']}' and evaluation '{setting['evaluation']}'")
        verification = {**config["ifenn"].get("verification", {}), **run.get("verification", {})}
        if verification.get("enabled") and setting["predictor"] != "picnn":
            problems.append(f"config key 'ifenn_runs.{name}.verification.enabled': verification checks the PICNN's "
                            f"prediction; it needs predictor 'picnn', got '{setting['predictor']}'")
        if setting["predictor"] == "picnn" and run["fem_run"] in config["fem_runs"]:
            problems += _network_material_problems(config, name, run["fem_run"])
        padding = run.get("pixel_padding", config["ifenn"].get("pixel_padding"))
        if verification.get("enabled") and padding not in ("replicate", "zeros"):
            problems.append(f"config key 'ifenn_runs.{name}.pixel_padding': the verified step's pixel equation needs "
                            f"'replicate' or 'zeros', got '{padding}'")
    return problems


def _specimen_differences(config: dict, a: dict, b: dict) -> list[str]:
    """What keeps two scenes from being the same specimen on other elements: the keys of their
    geometry, supports, plane and thickness that differ, and 'material' when theirs do."""
    different = [k for k in ("domain", "notches", "cutouts", "boundary", "plane", "thickness", "symmetry_factor") if a.get(k) != b.get(k)]
    return different + (["material"] if scene_material(config["material"], a) != scene_material(config["material"], b) else [])


def _finer_reference_problems(config: dict, key: str, entry: dict) -> list[str]:
    """A case's finer reference (``fine_fem_run``) must be the FEM run (``fem_run``)'s specimen, loads and
    solver settings on more elements (reference_convergence and adaptive_resolution alike)."""
    fem_runs = config.get("fem_runs", {})
    names = {field: entry[field] for field in ("fem_run", "fine_fem_run")}
    missing = [f for f, run in names.items() if run not in fem_runs]
    if missing:
        return [f"config key '{key}.{field}': '{names[field]}' is not a FEM run; allowed: {sorted(fem_runs)}" for field in missing]
    coarse, fine = fem_runs[entry["fem_run"]], fem_runs[entry["fine_fem_run"]]
    scene_c, scene_f = config["scenes"].get(coarse["scene"]), config["scenes"].get(fine["scene"])
    if scene_c is None or scene_f is None:
        return []  # the fem_runs check names the unknown scene
    problems = []
    different = _specimen_differences(config, scene_c, scene_f)
    different += [k for k in sorted(set(coarse) | set(fine)) if k not in ("scene", "save_fields") and coarse.get(k) != fine.get(k)]
    if different:
        problems.append(f"config key '{key}.fine_fem_run': '{entry['fine_fem_run']}' differs from '{entry['fem_run']}' in "
                        f"{different}; a finer reference may differ in the scene's elements only")
    if not all(f > c for f, c in zip(scene_f["elements"], scene_c["elements"], strict=False)):
        problems.append(f"config key '{key}.fine_fem_run': scene '{fine['scene']}' has {scene_f['elements']} elements, "
                        f"not more than '{coarse['scene']}' ({scene_c['elements']}) in both directions")
    return problems


def _reference_convergence_problems(config: dict) -> list[str]:
    """Each case's finer reference (:func:`_finer_reference_problems`) and the IFENN runs of its FEM run."""
    problems = []
    for case, entry in config.get("reference_convergence", {}).items():
        key = f"reference_convergence.{case}"
        problems += _finer_reference_problems(config, key, entry)
        if entry["fem_run"] in config.get("fem_runs", {}):
            problems += _runs_of_fem_run(f"{key}.ifenn_runs", entry["ifenn_runs"], config.get("ifenn_runs", {}), "an IFENN run",
                                         "continues", entry["fem_run"])
    return problems


def _runs_of_fem_run(key: str, names: list, pool: dict, kind: str, verb: str, fem_run: str) -> list[str]:
    """Each of ``names`` (config key ``key``) must be in ``pool`` and run ``fem_run``."""
    problems = []
    for k, run in enumerate(names):
        if run not in pool:
            problems.append(f"config key '{key}[{k}]': '{run}' is not {kind}; allowed: {sorted(pool)}")
        elif pool[run]["fem_run"] != fem_run:
            problems.append(f"config key '{key}[{k}]': '{run}' {verb} FEM run '{pool[run]['fem_run']}', not '{fem_run}'")
    return problems


def _adaptive_problems(config: dict, schema: dict) -> list[str]:
    """Adaptive runs: a FEM run (fixed or adaptive load steps), settings in range once merged, a
    trigger inside the buffer; adaptive_resolution cases name existing runs of their FEM run."""
    problems = []
    fem_runs, adaptive_runs = config.get("fem_runs", {}), config.get("adaptive_runs", {})
    settings_schema = schema["properties"]["adaptive_mesh"]
    validator = jsonschema.Draft202012Validator(settings_schema)
    for name, entry in adaptive_runs.items():
        key = f"adaptive_runs.{name}"
        if entry["fem_run"] not in fem_runs:
            problems.append(f"config key '{key}.fem_run': '{entry['fem_run']}' is not a FEM run; allowed: {sorted(fem_runs)}")
        ifenn_run = entry.get("ifenn_run")
        if ifenn_run is not None:
            ifenn_runs = config.get("ifenn_runs", {})
            if ifenn_run not in ifenn_runs:
                problems.append(f"config key '{key}.ifenn_run': '{ifenn_run}' is not an IFENN run; allowed: {sorted(ifenn_runs)}")
            elif ifenn_runs[ifenn_run]["fem_run"] != entry["fem_run"]:
                problems.append(f"config key '{key}.ifenn_run': '{ifenn_run}' continues FEM run '{ifenn_runs[ifenn_run]['fem_run']}', "
                                f"not '{entry['fem_run']}'")
            elif not deep_merge(config["ifenn"]["verification"], ifenn_runs[ifenn_run].get("verification", {}))["enabled"]:
                problems.append(f"config key '{key}.ifenn_run': '{ifenn_run}' is not verified; on an adaptive mesh the network's "
                                "answer is always checked (an IFENN run with verification.enabled)")
        if entry.get("schedule") is not None and entry["schedule"] not in config["schedules"]:
            problems.append(f"config key '{key}.schedule': '{entry['schedule']}' is not a schedule; allowed: {sorted(config['schedules'])}")
        if (scene := entry.get("scene")) is not None and entry["fem_run"] in fem_runs:
            own = fem_runs[entry["fem_run"]]["scene"]
            if scene not in config["scenes"]:
                problems.append(f"config key '{key}.scene': '{scene}' is not a scene; allowed: {sorted(config['scenes'])}")
            elif own in config["scenes"]:
                if different := _specimen_differences(config, config["scenes"][own], config["scenes"][scene]):
                    problems.append(f"config key '{key}.scene': '{scene}' differs from '{own}' (the scene of '{entry['fem_run']}') "
                                    f"in {different}; another scene of a run may differ in its elements only")
        merged = {**config["adaptive_mesh"], **entry.get("adaptive_mesh", {})}
        for err in validator.iter_errors(merged):
            where = ".".join(map(str, err.absolute_path)) or ""
            owner = f"{key}.adaptive_mesh" if (where.split(".")[0] in entry.get("adaptive_mesh", {}) or not where) else "adaptive_mesh"
            problems.append(f"config key '{owner}{'.' + where if where else ''}': {err.message}")
        presets = config["solver"]["linear_solver_presets"]
        if merged.get("linear_solvers") is not None and merged["linear_solvers"] not in presets:
            owner = f"{key}.adaptive_mesh" if "linear_solvers" in entry.get("adaptive_mesh", {}) else "adaptive_mesh"
            problems.append(f"config key '{owner}.linear_solvers': '{merged['linear_solvers']}' is not a preset; allowed: {sorted(presets)}")
        trigger, buffer = merged.get("trigger_lc", 1.5), merged.get("buffer_lc", 3.0)
        if isinstance(trigger, int | float) and isinstance(buffer, int | float) and trigger > buffer:
            problems.append(f"config key '{key}.adaptive_mesh.trigger_lc': {trigger} exceeds buffer_lc {buffer}; the mesh "
                                "must be rebuilt before the crack core leaves the fine region")
    for case, entry in config.get("adaptive_resolution", {}).items():
        key = f"adaptive_resolution.{case}"
        problems += _finer_reference_problems(config, key, entry)
        problems += _runs_of_fem_run(f"{key}.adaptive_runs", entry["adaptive_runs"], adaptive_runs, "an adaptive run", "runs",
                                     entry["fem_run"])
    return problems


def _switch_over_problems(config: dict) -> list[str]:
    """The switch-over criterion of every IFENN run (and the whole-path runs', :func:`_whole_path_problems`)."""
    problems = []
    runs = config.get("ifenn_runs", {})
    for name, entry in runs.items():
        criterion, increment = switch_over(config, name)
        key = f"ifenn_runs.{name}" if "switch_over" in entry else "ifenn"
        ikey = f"ifenn_runs.{name}.switch_increment" if {"switch_increment", "switch_over"} & set(entry) else "ifenn.switch_increment"
        if criterion not in SWITCH_OVER:  # the schema refuses it already; kept for configs built in code
            problems.append(f"config key '{key}.switch_over': '{criterion}' is not a criterion; allowed: {list(SWITCH_OVER)}")
        elif criterion == "increment":
            fem = config["fem_runs"].get(entry["fem_run"])
            n_inc = schedule_increments(config["schedules"].get(fem["schedule"], [])) if fem else None
            if increment is None:
                problems.append(f"config key '{ikey}': switch_over 'increment' (run '{name}') needs the FEM increment to switch "
                                f"after, got null; allowed: 1..{n_inc - 1 if n_inc else 'the last increment - 1'}")
            elif n_inc is not None and not 1 <= increment < n_inc:
                problems.append(f"config key '{ikey}': {increment} is outside the {n_inc} increments of run '{entry['fem_run']}' "
                                f"(allowed 1..{n_inc - 1}: IFENN computes the increments after it)")
        elif increment is not None and "switch_increment" in entry:
            problems.append(f"config key '{ikey}': {increment} is read only with switch_over 'increment', but run '{name}' "
                            f"switches by '{criterion}'; set switch_over: increment or remove it")
    if config["ifenn"].get("switch_increment") is not None and config["ifenn"].get("switch_over", "phi_threshold") != "increment":
        problems.append(f"config key 'ifenn.switch_increment': {config['ifenn']['switch_increment']} is read only with "
                        f"switch_over 'increment', got '{config['ifenn'].get('switch_over')}'")
    return problems + _whole_path_problems(config)


def _whole_path_problems(config: dict) -> list[str]:
    """The runs that name whole-path runs (whole_path, whole_run_benchmark) and the benchmark's pairs."""
    problems = []
    runs = config.get("ifenn_runs", {})
    for section in ("whole_path", "whole_run_benchmark"):
        for k, run in enumerate(config.get(section, {}).get("runs", [])):
            if run not in runs:
                problems.append(f"config key '{section}.runs[{k}]': '{run}' is not an IFENN run; allowed: {sorted(runs)}")
            elif switch_over(config, run)[0] != "start":
                problems.append(f"config key '{section}.runs[{k}]': '{run}' switches by '{switch_over(config, run)[0]}'; "
                                "a whole-path run needs switch_over 'start'")
    # the benchmark's runs are computed in one process with their FEM runs (ifenn.studies.drivers.whole_run_benchmark)
    paired = {}
    for k, run in enumerate(config.get("whole_run_benchmark", {}).get("runs", [])):
        fem_run = runs.get(run, {}).get("fem_run")
        if fem_run not in config["fem_runs"]:
            continue
        key = f"config key 'whole_run_benchmark.runs[{k}]'"
        if fem_run == config["picnn"]["training_run"]:
            problems.append(f"{key}: '{run}' runs on the network's training run '{fem_run}', which the network needs first, "
                            "and the benchmark computes a whole-path run with its FEM run: allowed, a run of another FEM run")
        if config["fem_runs"][fem_run].get("mpi_ranks", 1) > 1:
            problems.append(f"{key}: the FEM run '{fem_run}' of '{run}' runs on {config['fem_runs'][fem_run]['mpi_ranks']} MPI "
                            f"ranks; the benchmark runs it beside '{run}' in one process (allowed: mpi_ranks 1)")
        if fem_run in paired:
            problems.append(f"{key}: '{run}' and '{paired[fem_run]}' share the FEM run '{fem_run}'; allowed: one whole-path "
                            "run per FEM run")
        paired.setdefault(fem_run, run)
    for k, run in enumerate(config.get("whole_path", {}).get("network_runs", [])):
        if run not in config["whole_path"]["runs"]:
            problems.append(f"config key 'whole_path.network_runs[{k}]': '{run}' is not in whole_path.runs; "
                            f"allowed: {config['whole_path']['runs']}")
        elif runs[run].get("predictor", config["ifenn"]["predictor"]) != "picnn":
            problems.append(f"config key 'whole_path.network_runs[{k}]': '{run}' does not use the PICNN")
    return problems


def _network_material_problems(config: dict, name: str, fem_run: str) -> list[str]:
    """The network answers the pixel equation of the material it was trained on; another material
    at the same lc / h_px it answers through the equation's dimensionless form (its input scaled
    by H lc / Gc: ifenn.hybrid.runs.network_service), and where neither holds a verified run runs
    the certified pixel step without it. An unverified run of the network there is refused."""
    training_scene = config["scenes"].get(config["fem_runs"].get(config["picnn"]["training_run"], {}).get("scene"))
    scene = config["scenes"].get(config["fem_runs"][fem_run]["scene"])
    if training_scene is None or scene is None:
        return []
    trained, own = scene_material(config["material"], training_scene), scene_material(config["material"], scene)
    if all(math.isclose(trained[k], own[k], rel_tol=1e-12) for k in ("Gc", "lc")):
        return []

    run = config["ifenn_runs"][name]
    verified = {**config["ifenn"].get("verification", {}), **run.get("verification", {})}.get("enabled")
    ratio, trained_ratio = lc_over_h(config["material"], scene), lc_over_h(config["material"], training_scene)
    if math.isclose(ratio, trained_ratio, rel_tol=1e-6) or verified:
        return []
    return [f"config key 'ifenn_runs.{name}': the network was trained on Gc {trained['Gc']:g}, lc {trained['lc']:g} at "
            f"lc/h {trained_ratio:.4g}; this scene has Gc {own['Gc']:g}, lc {own['lc']:g} at lc/h "
            f"{ratio:.4g}, which no scaling of H maps onto it: run it verified (the certified pixel step "
            "takes over), with predictor 'exact_pixel', or at the network's lc/h"]
