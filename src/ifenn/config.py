"""Configuration: loading, schema validation, semantic checks and per-run specs.

The configuration is data (config/config.yaml): scenes, load schedules and runs. Every
check happens here, before any computation, and every error names the key, the value
and what is allowed.
"""

from __future__ import annotations

import copy
import functools
import hashlib
import json
import math
from pathlib import Path
from typing import Any

import jsonschema
import yaml

from ifenn import geometry
from ifenn.fem import supports
from ifenn.network.settings import resolve_settings
from ifenn.schema import REPO, SCHEMA_PATH, _schema  # noqa: F401 (REPO: for the benchmarks)

EDGES = ("left", "right", "bottom", "top")
# speed_accuracy: method -> the config section of its runs
#: the coarsest mesh accepted for a scene: AT2's profile exp(-|x|/lc) over at least two elements a
#: length scale (the paper's scenes have 6 to 9; the stability sweep probes 3)
MIN_LC_OVER_H = 2.0
SPEED_ACCURACY_METHODS = {"fem": "fem_runs", "ifenn": "ifenn_runs", "adaptive": "adaptive_runs"}


class ConfigError(ValueError):
    """A configuration value is missing, of the wrong type or out of range."""


def deep_merge(base: dict, override: dict) -> dict:
    """Recursively merge ``override`` into a copy of ``base`` (lists are replaced whole),
    the way Snakemake merges ``--configfile`` files."""
    merged = copy.deepcopy(base)
    for key, value in override.items():
        if isinstance(value, dict) and isinstance(merged.get(key), dict):
            merged[key] = deep_merge(merged[key], value)
        else:
            merged[key] = copy.deepcopy(value)
    return merged


def load_config(*paths: str | Path) -> dict:
    """Read and merge YAML files in order, then validate; returns the checked config."""
    config: dict = {}
    for path in paths:
        with open(path) as stream:
            config = deep_merge(config, yaml.safe_load(stream) or {})
    return validate_config(config)


def _key_path(path) -> str:
    out = ""
    for part in path:
        out += f"[{part}]" if isinstance(part, int) else (f".{part}" if out else str(part))
    return out or "<top level>"


def _fill_defaults(instance: Any, schema: dict, root: dict) -> None:
    """Insert the schema's ``default`` values for missing properties (in place)."""
    if "$ref" in schema:
        schema = root["$defs"][schema["$ref"].split("/")[-1]]
    for branch in schema.get("oneOf", []):  # the branch of the instance's type (validated already)
        if branch.get("type") == {dict: "object", list: "array"}.get(type(instance)):
            _fill_defaults(instance, branch, root)
    if isinstance(instance, dict):
        for key, sub in schema.get("properties", {}).items():
            if key not in instance and "default" in sub:
                instance[key] = copy.deepcopy(sub["default"])
            if key in instance:
                _fill_defaults(instance[key], sub, root)
        extra = schema.get("additionalProperties")
        if isinstance(extra, dict):
            for key, value in instance.items():
                if key not in schema.get("properties", {}):
                    _fill_defaults(value, extra, root)
    elif isinstance(instance, list) and isinstance(schema.get("items"), dict):
        for item in instance:
            _fill_defaults(item, schema["items"], root)


def _specific(errors):
    """Errors of a 'oneOf' (e.g. a schedule: list of segments or adaptive) replaced by those of
    the branch of the value's type, so the message names the key and value that are wrong."""
    for err in errors:
        inner = [e for e in err.context if e.validator != "type" or len(e.relative_path)] if err.validator == "oneOf" else []
        yield from (_specific(inner) if inner else [err])


def _non_finite(instance: Any, path: tuple = ()) -> list[str]:
    """Every float of the config that is NaN or infinite (YAML's .nan, .inf), by key. Checked
    once for all keys, before the schema: a NaN fails every comparison, so a range check
    (minimum, maximum, a < b) alone would let it through to the solvers."""
    if isinstance(instance, float) and not math.isfinite(instance):
        return [f"config key '{_key_path(path)}': {instance!r} is not a finite number"]
    if isinstance(instance, dict):
        return [p for key, value in instance.items() for p in _non_finite(value, (*path, key))]
    if isinstance(instance, list):
        return [p for i, value in enumerate(instance) for p in _non_finite(value, (*path, i))]
    return []


def validate_config(config: dict, schema_path: Path = SCHEMA_PATH, petsc_names: bool = True) -> dict:
    """Validate against the JSON schema, fill defaults, then check cross-references and
    geometry. Returns a new, completed config; raises ConfigError listing every problem.

    ``petsc_names``: check PETSc type names against PETSc's own (read in a child process, ~1 s:
    :func:`_petsc_type_names`); the jobs' Snakemake processes skip it, the main one checked."""
    schema = _schema(Path(schema_path))
    validator = jsonschema.Draft202012Validator(schema)
    problems = _non_finite(config) + [
        f"config key '{_key_path(err.absolute_path)}': {err.message}"
        for err in sorted(_specific(validator.iter_errors(config)), key=lambda e: list(map(str, e.absolute_path)))
    ]
    if problems:
        raise ConfigError("invalid configuration:\n  " + "\n  ".join(problems))
    config = copy.deepcopy(config)
    _fill_defaults(config, schema, schema)
    for fine, name in finer_reference_runs(config).items():
        if name != fine:
            config["adaptive_runs"].setdefault(name, {"fem_run": fine, "adaptive_mesh": dict(config["finer_reference_mesh"])})
    problems = _semantic_problems(config, petsc_names) + _adaptive_problems(config, schema)
    if problems:
        raise ConfigError("invalid configuration:\n  " + "\n  ".join(problems))
    return config


#: PETSc options whose value names a PETSc type, and the petsc4py enumeration of its names
_PETSC_TYPE_OPTIONS = {"ksp_type": "KSP", "pc_type": "PC", "pc_factor_mat_solver_type": "SOLVER", "pc_factor_mat_ordering_type": "ORDERING"}


_PETSC_NAMES_SCRIPT = """
import json
from petsc4py import PETSc
enums = {"KSP": PETSc.KSP.Type, "PC": PETSc.PC.Type, "SOLVER": PETSc.Mat.SolverType, "ORDERING": PETSc.Mat.OrderingType}
print(json.dumps({kind: sorted({getattr(e, n) for n in dir(e) if not n.startswith("_") and isinstance(getattr(e, n), str)})
                  for kind, e in enums.items()}))
"""


@functools.cache
def _petsc_type_names() -> dict | None:
    """PETSc's type names by kind (KSP, PC, SOLVER, ORDERING), read in a child process: importing
    petsc4py starts MPI, and a Snakemake process with MPI started passes MPI's environment to
    the jobs it submits (sbatch --export=ALL), where mpirun then exits 1 without a word (seen
    under SLURM). None where petsc4py is missing (PETSc checks the names when a run starts)."""
    import importlib.util
    import subprocess
    import sys

    if importlib.util.find_spec("petsc4py") is None:
        return None
    done = subprocess.run([sys.executable, "-c", _PETSC_NAMES_SCRIPT], capture_output=True, text=True)
    return json.loads(done.stdout) if done.returncode == 0 else None


def _python_class_exists(path: str) -> bool:
    """Whether ``module.Class`` names a class defined in a module found on the path. Read, not
    imported: importing it here would initialise PETSc and MPI in the Snakemake process, whose
    mpirun children then fail without a word (Open MPI's singleton environment)."""
    import ast
    import importlib.util

    module, _, name = path.rpartition(".")
    try:
        found = importlib.util.find_spec(module) if module else None
    except (ImportError, ValueError):
        return False
    if found is None or not found.origin or not found.origin.endswith(".py"):
        return False
    tree = ast.parse(Path(found.origin).read_text())
    return any(isinstance(node, ast.ClassDef) and node.name == name for node in tree.body)


def _petsc_problems(key: str, options: dict) -> list[str]:
    """Values of PETSc options that PETSc would refuse only inside a run: an unknown type name
    (``ksp_type``, ``pc_type``, the factor's solver and ordering, also behind a ``sub_`` or
    ``mg_levels_`` prefix) and a tolerance or iteration limit that is not a positive number."""
    names = _petsc_type_names() or {}
    problems = []
    for option, value in options.items():
        base = option.removeprefix("sub_").removeprefix("mg_levels_").removeprefix("mg_coarse_")
        if base in _PETSC_TYPE_OPTIONS:
            allowed = names.get(_PETSC_TYPE_OPTIONS[base])
            if allowed is not None and str(value) not in allowed:
                problems.append(f"config key '{key}.{option}': {value!r} is not a PETSc type of that kind; allowed: {allowed}")
        elif base == "pc_python_type" and not _python_class_exists(str(value)):   # a python preconditioner
            problems.append(f"config key '{key}.{option}': {value!r} is not a module.Class found here "
                            "(e.g. ifenn.fem.factor.NestedDissectionCholesky)")
        elif base.endswith(("_rtol", "_atol", "_max_it")):
            integral = base.endswith("_max_it")
            good = isinstance(value, int if integral else (int, float)) and not isinstance(value, bool) and value > 0
            if not good:
                problems.append(f"config key '{key}.{option}': {value!r} must be a positive {'integer' if integral else 'number'}")
    return problems


def _semantic_problems(config: dict, petsc_names: bool = True) -> list[str]:
    problems: list[str] = []
    if config.get("device") == "cuda":   # torch is imported only for this (ifenn.device)
        from ifenn.device import resolve_device

        try:
            resolve_device("cuda")
        except ValueError as error:
            problems.append(str(error))
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
                problems += _petsc_problems(f"solver.linear_solver_presets.{name}.{field}", preset[field])
    for name, scene in config["scenes"].items():
        key = f"scenes.{name}"
        (x0, x1), (y0, y1) = scene["domain"]["x"], scene["domain"]["y"]
        if not (x0 < x1 and y0 < y1):
            problems.append(f"config key '{key}.domain': need x[0] < x[1] and y[0] < y[1], got {scene['domain']}")
            continue
        hx, hy = (x1 - x0) / scene["elements"][0], (y1 - y0) / scene["elements"][1]
        if abs(hx - hy) > 1e-9 * hx:  # the test of ifenn.fem.mesh.element_size, before any mesh is built
            problems.append(f"config key '{key}.elements': {scene['elements']} on the domain {scene['domain']} gives "
                            f"{hx:g} x {hy:g} mm elements; the pixel map needs square ones (allowed: elements "
                            f"proportional to the domain's sides, {(x1 - x0) / (y1 - y0):g} : 1)")
        problems += geometry.cutout_problems(scene, key)
        problems += supports.problems(scene, key)
        lc = scene_material(config["material"], scene)["lc"]
        lc_key = f"{key}.material.lc" if "lc" in scene.get("material", {}) else "material.lc"
        if lc < MIN_LC_OVER_H * hx:
            problems.append(f"config key '{lc_key}': lc = {lc:g} mm is {lc / hx:.3g} elements of scene '{name}' "
                            f"(h = {hx:g} mm); the mesh resolves the phase field from lc/h = {MIN_LC_OVER_H:g} on: "
                            f"refine the scene's elements to at least {math.ceil(MIN_LC_OVER_H * (x1 - x0) / lc)} across x")
        if lc >= min(x1 - x0, y1 - y0):
            problems.append(f"config key '{lc_key}': lc = {lc:g} mm is not smaller than scene '{name}' "
                            f"({x1 - x0:g} x {y1 - y0:g} mm): the phase field would span the specimen")
        own = scene.get("material", {})
        if ("E" in own) != ("nu" in own):
            problems.append(f"config key '{key}.material': give E and nu together (or lame_lambda and lame_mu), got {sorted(own)}")
        if ("E" in own) and ({"lame_lambda", "lame_mu"} & set(own)):
            problems.append(f"config key '{key}.material': give either E and nu or lame_lambda and lame_mu, not both")
        if ("lame_lambda" in own) != ("lame_mu" in own):
            problems.append(f"config key '{key}.material': give lame_lambda and lame_mu together, got {sorted(own)}")
        tol = 1e-12 * max(x1 - x0, y1 - y0)
        for i, notch in enumerate(scene.get("notches", [])):
            nkey = f"{key}.notches[{i}]"
            for end in ("start", "end"):
                px, py = notch[end]
                if not (x0 - tol <= px <= x1 + tol and y0 - tol <= py <= y1 + tol):
                    problems.append(
                        f"config key '{nkey}.{end}': point {notch[end]} lies outside the domain "
                        f"x in [{x0}, {x1}], y in [{y0}, {y1}]"
                    )
            (sx, sy), (ex, ey) = notch["start"], notch["end"]
            if notch["kind"] == "slit" and abs(sx - ex) > tol and abs(sy - ey) > tol:
                problems.append(
                    f"config key '{nkey}': a slit must be horizontal or vertical (along mesh lines), "
                    f"got {notch['start']} -> {notch['end']}; use kind 'history' for other notches"
                )
            if abs(sx - ex) <= tol and abs(sy - ey) <= tol:
                problems.append(f"config key '{nkey}': start and end coincide")
            elif notch["kind"] == "slit" and not notch.get("snap", False):
                off = [c for c, o in ((sx, x0), (sy, y0), (ex, x0), (ey, y0)) if not geometry.on_grid(c, o, hx)]
                if off:
                    problems.append(
                        f"config key '{nkey}': the slit {notch['start']} -> {notch['end']} has coordinates {off} "
                        f"between mesh lines (every {hx:g} mm from ({x0:g}, {y0:g})); it is not snapped: move its "
                        f"ends, change the elements, or set '{nkey}.snap: true' to move it to the nearest line")
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
    problems += _switch_over_problems(config)
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
        if not (REPO / specimen["measured"]["file"]).is_file():
            problems.append(f"config key 'specimens.{name}.measured.file': no file {specimen['measured']['file']} in the repository")
    problems += _reference_convergence_problems(config)
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


def _specimen_differences(config: dict, a: dict, b: dict) -> list[str]:
    """What keeps two scenes from being the same specimen on other elements: the keys of their
    geometry, supports, plane and thickness that differ, and 'material' when theirs do."""
    different = [k for k in ("domain", "notches", "cutouts", "boundary", "plane", "thickness", "symmetry_factor") if a.get(k) != b.get(k)]
    return different + (["material"] if scene_material(config["material"], a) != scene_material(config["material"], b) else [])


def _reference_convergence_problems(config: dict) -> list[str]:
    """A finer reference must be the same specimen, loads and solver settings on more elements."""
    problems = []
    fem_runs, ifenn_runs = config.get("fem_runs", {}), config.get("ifenn_runs", {})
    for case, entry in config.get("reference_convergence", {}).items():
        key = f"reference_convergence.{case}"
        names = {field: entry[field] for field in ("fem_run", "fine_fem_run")}
        missing = [f for f, run in names.items() if run not in fem_runs]
        for field in missing:
            problems.append(f"config key '{key}.{field}': '{names[field]}' is not a FEM run; allowed: {sorted(fem_runs)}")
        if missing:
            continue
        coarse, fine = fem_runs[entry["fem_run"]], fem_runs[entry["fine_fem_run"]]
        scene_c, scene_f = config["scenes"].get(coarse["scene"]), config["scenes"].get(fine["scene"])
        if scene_c is None or scene_f is None:
            continue  # the fem_runs check names the unknown scene
        different = _specimen_differences(config, scene_c, scene_f)
        different += [k for k in sorted(set(coarse) | set(fine)) if k not in ("scene", "save_fields") and coarse.get(k) != fine.get(k)]
        if different:
            problems.append(f"config key '{key}.fine_fem_run': '{entry['fine_fem_run']}' differs from '{entry['fem_run']}' in "
                            f"{different}; a finer reference may differ in the scene's elements only")
        if not all(f > c for f, c in zip(scene_f["elements"], scene_c["elements"], strict=False)):
            problems.append(f"config key '{key}.fine_fem_run': scene '{fine['scene']}' has {scene_f['elements']} elements, "
                            f"not more than '{coarse['scene']}' ({scene_c['elements']}) in both directions")
        problems += _runs_of_fem_run(f"{key}.ifenn_runs", entry["ifenn_runs"], ifenn_runs, "an IFENN run", "continues",
                                     entry["fem_run"])
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
        for field in ("fem_run", "fine_fem_run"):
            if entry[field] not in fem_runs:
                problems.append(f"config key '{key}.{field}': '{entry[field]}' is not a FEM run; allowed: {sorted(fem_runs)}")
        problems += _runs_of_fem_run(f"{key}.adaptive_runs", entry["adaptive_runs"], adaptive_runs, "an adaptive run", "runs",
                                     entry["fem_run"])
    return problems


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
    return spec


SWITCH_OVER = ("phi_threshold", "increment", "start")


def paired_runs(config: dict) -> dict[str, str]:
    """FEM run -> whole-path IFENN run, for the runs of 'whole_run_benchmark': the workflow computes
    each pair in one process, increments interleaved, and the benchmark reads their histories
    (:func:`ifenn.studies.whole_run_benchmark.paired_whole_run`); {} without the section."""
    return {config["ifenn_runs"][run]["fem_run"]: run for run in (config.get("whole_run_benchmark") or {}).get("runs", [])}


def switch_over(config: dict, run: str) -> tuple[str, int | None]:
    """(criterion, switch increment) of an IFENN run: its entry's ``switch_over`` /
    ``switch_increment``, else the 'ifenn' section's (criteria in SWITCH_OVER)."""
    entry = config["ifenn_runs"][run]
    return (entry.get("switch_over", config["ifenn"].get("switch_over", "phi_threshold")),
            entry.get("switch_increment", config["ifenn"].get("switch_increment")))


def _switch_over_problems(config: dict) -> list[str]:
    """The switch-over criterion of every IFENN run, and the runs that name whole-path runs."""
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
    for section in ("whole_path", "whole_run_benchmark"):
        for k, run in enumerate(config.get(section, {}).get("runs", [])):
            if run not in runs:
                problems.append(f"config key '{section}.runs[{k}]': '{run}' is not an IFENN run; allowed: {sorted(runs)}")
            elif switch_over(config, run)[0] != "start":
                problems.append(f"config key '{section}.runs[{k}]': '{run}' switches by '{switch_over(config, run)[0]}'; "
                                "a whole-path run needs switch_over 'start'")
    # the benchmark's runs are computed in one process with their FEM runs (ifenn.studies.whole_run_benchmark)
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

    def lc_over_h(sc, material):
        return material["lc"] / ((sc["domain"]["x"][1] - sc["domain"]["x"][0]) / sc["elements"][0])

    run = config["ifenn_runs"][name]
    verified = {**config["ifenn"].get("verification", {}), **run.get("verification", {})}.get("enabled")
    if math.isclose(lc_over_h(scene, own), lc_over_h(training_scene, trained), rel_tol=1e-6) or verified:
        return []
    return [f"config key 'ifenn_runs.{name}': the network was trained on Gc {trained['Gc']:g}, lc {trained['lc']:g} at "
            f"lc/h {lc_over_h(training_scene, trained):.4g}; this scene has Gc {own['Gc']:g}, lc {own['lc']:g} at lc/h "
            f"{lc_over_h(scene, own):.4g}, which no scaling of H maps onto it: run it verified (the certified pixel step "
            "takes over), with predictor 'exact_pixel', or at the network's lc/h"]


def scene_material(material: dict, scene: dict) -> dict:
    """The material a run of ``scene`` uses: the config's, with the scene's own ``material`` merged
    over it (E and nu become the Lame pair: lambda = E nu / ((1 + nu)(1 - 2 nu)), mu = E / (2 (1 +
    nu))), and the scene's ``plane`` and ``thickness`` where it sets them (so a scene that sets none
    resolves to the config's material exactly)."""
    resolved = dict(material)
    own = dict(scene.get("material", {}))
    if "E" in own and "nu" in own:   # (E alone is refused by the checks)
        E, nu = own.pop("E"), own.pop("nu")
        own["lame_lambda"], own["lame_mu"] = E * nu / ((1 + nu) * (1 - 2 * nu)), E / (2 * (1 + nu))
    resolved.update(own)
    for key in ("plane", "thickness"):
        if key in scene:
            resolved[key] = scene[key]
    return resolved


def training_spec(config: dict) -> dict:
    """What the training rules need: the PICNN section, material and the training run's scene
    (its slits cut the loss's stencil, as in every pixel operator)."""
    scene = config["scenes"][config["fem_runs"][config["picnn"]["training_run"]]["scene"]]
    return {**config["picnn"], "material": scene_material(config["material"], scene), "scene": scene}


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
    return {
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
    }


#: what may differ between two runs whose first increments are the same computation
PREFIX_FREE_KEYS = ("name", "fem_run", "schedule_name", "load", "save_fields")


def _longest_shared_prefix(spec: dict, others: dict[str, dict]) -> dict | None:
    """The run of ``others`` (name -> spec) whose saved state ``spec`` can start from
    (:func:`shared_prefix`): {'run', 'increment', 'spec_hash'}, or None."""
    if "load" not in spec:
        return None
    rest = {k: v for k, v in spec.items() if k not in PREFIX_FREE_KEYS}
    best = None
    for other in sorted(others):
        candidate = others[other]
        if other == spec["name"] or "load" not in candidate or (len(candidate["load"]), other) >= (len(spec["load"]), spec["name"]):
            continue
        if {k: v for k, v in candidate.items() if k not in PREFIX_FREE_KEYS} != rest:
            continue
        common = 0
        for mine, theirs in zip(spec["load"], candidate["load"], strict=False):
            if mine != theirs:
                break
            common += 1
        saved = set(candidate["save_fields"])
        own = sorted(spec["save_fields"])
        ends = [k for k in sorted(saved) if k <= min(common, len(spec["load"]) - 1) and all(i in saved for i in own if i <= k)]
        if ends and (best is None or ends[-1] > best["increment"]):
            best = {"run": other, "increment": ends[-1], "spec_hash": spec_hash(candidate)}
    return best


def shared_prefix(config: dict, run: str) -> dict | None:
    """The saved state of another FEM run that ``run`` can start from (config
    ``solver.share_load_prefix``): {'run', 'increment' k, 'spec_hash' of that run}, or None.

    Two FEM runs compute the same first k increments when their specs agree but for the loads
    and the saved increments (PREFIX_FREE_KEYS) and their prescribed displacements agree exactly
    on increments 1..k (schedule III repeats schedule II's first 500 increments). The other run
    must have saved increment k and every increment ``run`` saves up to k (its switch-over
    state too: the same rows, the same switch), and, so that no two runs wait on each other,
    have fewer increments (ties: the name first in order). The longest k wins. Only FEM runs
    with fixed schedules share; a whole-run benchmark's FEM run never starts from another
    (it times the whole run)."""
    if not config["solver"].get("share_load_prefix", False) or run in paired_runs(config):
        return None
    return _longest_shared_prefix(fem_run_spec(config, run), {name: fem_run_spec(config, name) for name in config["fem_runs"]})


def adaptive_shared_prefix(config: dict, run: str) -> dict | None:
    """:func:`shared_prefix` for the runs on the adaptive mesh (``adaptive_runs``): the state of a
    run there is its pixel images and fine regions, which it saves with each increment. A verified
    IFENN run never shares (its network step keeps state of its own between increments)."""
    def spec(name):
        return adaptive_run_spec(config, name)

    def verified(s):
        return bool((s.get("verification") or {}).get("enabled"))

    if not config["solver"].get("share_load_prefix", False) or verified(mine := spec(run)):
        return None
    others = {name: s for name in config.get("adaptive_runs", {}) if not verified(s := spec(name))}
    return _longest_shared_prefix(mine, others)


IFENN_OPTIONS = ("predictor", "evaluation", "history_cap", "smoothing_sigma", "smoothing_truncate", "irreversible", "pixel_padding")


def ifenn_run_spec(config: dict, run: str) -> dict:
    """An IFENN run: the spec of its FEM run (scene, schedule, solvers, switch threshold)
    plus the hybrid options (config 'ifenn', overridden per run). The switch-over criterion
    (``switch_over``, ``switch_increment``) is in the spec only when it is not the paper's
    phi threshold."""
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
    if criterion != "phi_threshold":  # in the spec only when not the paper's (the published runs' specs stay as they were)
        spec["switch_over"] = criterion
        if criterion == "increment":
            spec["switch_increment"] = increment
    return spec


def spec_hash(spec: dict) -> str:
    """Stable short hash of a spec (canonical JSON), recorded in provenance and checkpoints."""
    text = json.dumps(spec, sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()[:16]
