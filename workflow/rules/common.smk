# Validate the configuration before any job starts; helpers shared by the rules.
import json
import re
import sys
from types import SimpleNamespace

from snakemake.settings.types import DeploymentMethod

from ifenn.config import (ConfigError, adaptive_run_spec, adaptive_shared_prefix, fem_run_spec, finer_reference_dir, finer_reference_runs, ifenn_run_spec,
                          paired_runs, schedule_increments, shared_prefix, speed_accuracy_setups, switch_over, training_spec,
                          validate_config)
from ifenn.studies.drivers import stability as _stability
from ifenn.studies.tables.metrics import process_zone_pairs
from ifenn import materials
from ifenn.studies.tables.specimens import symmetry_factor

try:
    # PETSc's type names once, in the main process (a child process reads them: petsc4py would
    # start MPI here, and its environment would reach the jobs; ifenn.config.petsc_names)
    _validated = validate_config(config, petsc_names=workflow.is_main_process)
except ConfigError as error:
    raise WorkflowError(str(error)) from None
config.clear()
config.update(_validated)

# Shell rules start the package's CLI with this interpreter: Snakemake's own (the venv of `make`),
# or, with --software-deployment-method conda, the `python` of the rule's environment.
PYTHON = "python" if DeploymentMethod.CONDA in workflow.deployment_settings.deployment_method else sys.executable
SCRIPTS = os.path.join(workflow.basedir, "workflow", "scripts")
MPI_LAUNCHER = "mpirun -n {ranks} --oversubscribe"


# The FEM runs `all` asks for by name: every one but the finer references that run on the adaptive
# mesh instead (finer_references: adaptive); a rule that reads such a run still pulls it in.
ALL_FEM_RUNS = [run for run in config["fem_runs"] if finer_reference_runs(config).get(run, run) == run]


# FEM run -> whole-path IFENN run computed with it in one process by the whole-run benchmark's
# rule (whole_path.smk); the rules fem and ifenn leave these runs to it (their wildcard patterns).
PAIRED_RUNS = paired_runs(config)


def run_pattern(excluded):
    """A {run} wildcard's pattern that matches any run name but those of ``excluded`` (the name is
    followed by '/' in every output of the rules that use it)."""
    if not excluded:
        return "[^/]+"
    return "(?!(?:" + "|".join(re.escape(name) for name in sorted(excluded)) + ")/)[^/]+"


def identifier(name):
    """A run name as a rule-name suffix (letters, digits, _)."""
    return re.sub(r"\W", "_", name)


_STARTS = {}


def run_start(kind, run):
    """The saved state of another run of ``kind`` (fem, adaptive) this one starts from
    (ifenn.config.shared_prefix / adaptive_shared_prefix), or None."""
    if (kind, run) not in _STARTS:
        _STARTS[kind, run] = (shared_prefix if kind == "fem" else adaptive_shared_prefix)(config, run)
    return _STARTS[kind, run]


def start_inputs(kind, run):
    """The outputs of the run ``run`` starts from (none when it starts from its first increment)."""
    start = run_start(kind, run)
    return {} if start is None else {"start_fields": f"results/{kind}/{start['run']}/fields.h5",
                                     "start_history": f"results/{kind}/{start['run']}/history.csv"}


def start_argument(kind):
    """The rule's --start-dir argument (empty when the run starts from its first increment)."""
    def argument(wildcards):
        start = run_start(kind, wildcards.run)
        return "" if start is None else f"--start-dir results/{kind}/{start['run']}"

    return argument


def run_spec_json(kind, run):
    """A run's spec (fem, adaptive) as the workflow runs it: with ``start_from`` where it starts
    from another run's saved state (run_start)."""
    spec = (fem_run_spec if kind == "fem" else adaptive_run_spec)(config, run)
    start = run_start(kind, run)
    return json.dumps({**spec, "start_from": start} if start else spec, sort_keys=True)


def _fem_cost(run):
    """A FEM run's expected cost: the increments it computes (not those it takes over from the run
    it starts from, run_start) x elements x staggered passes (3 when converged; an adaptive
    schedule counts as 1000 increments)."""
    entry = config["fem_runs"][run]
    increments = schedule_increments(config["schedules"][entry["schedule"]]) or 1000
    start = run_start("fem", run)
    nx, ny = config["scenes"][entry["scene"]]["elements"]
    passes = 3 if entry.get("stagger_max_iterations", config["solver"]["stagger_max_iterations"]) > 1 else 1
    return (increments - (start["increment"] if start else 0)) * nx * ny * passes


def _fem_path(run):
    """The cost of a FEM run and of the longest chain of runs that start from it (they wait for it)."""
    after = [other for other in config["fem_runs"] if (run_start("fem", other) or {}).get("run") == run]
    return _fem_cost(run) + max((_fem_path(other) for other in after), default=0)


def fem_priority(wildcards):
    """Scheduling priority of a FEM run: the PICNN's training run first (every IFENN run waits
    for the network), then the others longest path first (10..90: a run and those that start
    from its state), so the longest chain does not start last behind short ones."""
    if wildcards.run == config["picnn"]["training_run"]:
        return 100
    longest = max(_fem_path(run) for run in config["fem_runs"])
    return 10 + int(80 * _fem_path(wildcards.run) / longest)


def lc_over_h(fem_run):
    return materials.lc_over_h(config["material"], config["scenes"][config["fem_runs"][fem_run]["scene"]])


def fem_ranks(wildcards):
    return config["fem_runs"][wildcards.run].get("mpi_ranks", 1)


def fem_launcher(wildcards):
    ranks = fem_ranks(wildcards)
    return MPI_LAUNCHER.format(ranks=ranks) if ranks > 1 else ""


def ifenn_inputs(wildcards):
    """An IFENN run's spec, mesh, network and, unless it starts from the initial state
    (switch_over 'start'), the FEM run it continues."""
    entry = config["ifenn_runs"][wildcards.run]
    fem_run = entry["fem_run"]
    inputs = {
        "spec": f"results/ifenn/{wildcards.run}/spec.json",
        "mesh": f"results/mesh/{config['fem_runs'][fem_run]['scene']}.xdmf",
    }
    if switch_over(config, wildcards.run)[0] != "start":
        inputs.update(fem_fields=f"results/fem/{fem_run}/fields.h5", fem_history=f"results/fem/{fem_run}/history.csv")
    if entry.get("predictor", config["ifenn"]["predictor"]) == "picnn":
        inputs["model"] = "results/picnn/model.pt"
    return inputs


def ifenn_pair(run):
    """Histories and fields of an IFENN run and of the FEM run it continues."""
    fem_run = config["ifenn_runs"][run]["fem_run"]
    return {"fem_history": f"results/fem/{fem_run}/history.csv", "fem_fields": f"results/fem/{fem_run}/fields.h5",
            "ifenn_history": f"results/ifenn/{run}/history.csv", "ifenn_fields": f"results/ifenn/{run}/fields.h5"}


def comparison_inputs(run):
    """The FEM/IFENN pair of a comparison figure, and the verified IFENN run drawn beside it."""
    inputs = ifenn_pair(run)
    verified = config["figures"]["comparisons"][run].get("verified")
    if verified:
        inputs.update(verified_history=f"results/ifenn/{verified}/history.csv", verified_fields=f"results/ifenn/{verified}/fields.h5")
    return inputs


def run_pairs():
    """IFENN run -> its FEM run's name and both run directories, for every IFENN run."""
    return {run: {"fem_run": entry["fem_run"], "fem_dir": f"results/fem/{entry['fem_run']}", "ifenn_dir": f"results/ifenn/{run}"}
            for run, entry in config["ifenn_runs"].items()}


def speed_accuracy_dirs():
    """{"fem": {run: directory}, "ifenn": {run: directory}, "adaptive": {run: directory}} of the speed-accuracy runs."""
    setups = speed_accuracy_setups(config).values()
    return {"fem": {r: f"results/fem/{r}" for s in setups for r in s.get("fem", [])},
            "ifenn": {r: f"results/ifenn/{r}" for s in setups for r in s.get("ifenn", [])},
            "adaptive": {r: f"results/adaptive/{r}" for s in setups for r in s.get("adaptive", [])}}


def speed_accuracy_inputs(wildcards):
    return sorted(f"{d}/{name}" for dirs in speed_accuracy_dirs().values() for d in dirs.values() for name in ("history.csv", "spec.json"))


PROCESS_ZONE_PAIRS = process_zone_pairs(config)

STABILITY_CELLS = _stability.cells(config) if config.get("stability") else {}


def stability_cell_inputs(wildcards):
    cell = STABILITY_CELLS[wildcards.cell]
    inputs = {"spec": f"results/stability/{wildcards.cell}/spec.json"}
    if cell["method"] == "ifenn":
        inputs["fem_status"] = f"results/stability/{cell['fem_cell']}/status.json"
        if cell["spec"]["predictor"] == "picnn":
            inputs["model"] = "results/picnn/model.pt"
    return inputs


def all_cores(wildcards):
    """Every core Snakemake was given (a job that must run alone); 1 where none is set (--report)."""
    try:
        return workflow.cores
    except WorkflowError:
        return 1


def benchmark_cores(wildcards):
    """A speed benchmark's threads: every core (nothing beside it) with config benchmarks_alone,
    else one (its methods are interleaved in one process, so their ratios hold under load)."""
    return all_cores(wildcards) if config.get("benchmarks_alone", False) else 1


def error_sources_cases(wildcards):
    """Per run: its spec, mesh, FEM run folder, published IFENN history and the network."""
    cases = []
    for run in config["error_sources"]["runs"]:
        fem_run = config["ifenn_runs"][run]["fem_run"]
        cases.append({"spec": f"results/ifenn/{run}/spec.json", "mesh": f"results/mesh/{config['fem_runs'][fem_run]['scene']}.xdmf",
                      "fem_dir": f"results/fem/{fem_run}", "ifenn_history": f"results/ifenn/{run}/history.csv",
                      "model": "results/picnn/model.pt"})
    return cases


def error_sources_inputs(wildcards):
    paths = set()
    for case in error_sources_cases(wildcards):
        paths |= {case["spec"], case["mesh"], case["ifenn_history"], case["model"],
                  f"{case['fem_dir']}/fields.h5", f"{case['fem_dir']}/history.csv"}
    return sorted(paths)


def whole_path_runs():
    """Whole-path IFENN run -> the FEM run of the same scene and schedule (config 'whole_path')."""
    return {run: config["ifenn_runs"][run]["fem_run"] for run in config["whole_path"]["runs"]}


def whole_path_dirs():
    """Whole-path IFENN run -> its FEM run's name and both run directories."""
    return {run: {"fem_run": fem, "fem_dir": f"results/fem/{fem}", "ifenn_dir": f"results/ifenn/{run}"}
            for run, fem in whole_path_runs().items()}


def reference_convergence_dirs():
    """Case of config 'reference_convergence' -> its runs and their directories."""
    return {case: {"fem_run": entry["fem_run"], "fine_fem_run": entry["fine_fem_run"],
                   "fem_dir": f"results/fem/{entry['fem_run']}", "fine_dir": finer_reference_dir(config, entry["fine_fem_run"]),
                   "ifenn_dirs": {run: f"results/ifenn/{run}" for run in entry["ifenn_runs"]}}
            for case, entry in config.get("reference_convergence", {}).items()}


def whole_path_network_cases():
    """The pre-nucleation replay's runs: spec, FEM fields, the network and the run's history."""
    return {run: {"spec": f"results/ifenn/{run}/spec.json", "fem_fields": f"results/fem/{config['ifenn_runs'][run]['fem_run']}/fields.h5",
                  "model": "results/picnn/model.pt", "history": f"results/ifenn/{run}/history.csv"}
            for run in config["whole_path"].get("network_runs", [])}


def whole_path_inputs(wildcards):
    """FEM and whole-path histories; for the network replay the spec, the FEM fields and the network."""
    setup = config["whole_path"]
    paths = {f"results/fem/{fem}/{name}" for fem in whole_path_runs().values() for name in ("history.csv", "spec.json")}
    paths |= {f"results/ifenn/{run}/history.csv" for run in setup["runs"]}
    for run in setup.get("network_runs", []):
        paths |= {f"results/ifenn/{run}/spec.json", f"results/fem/{config['ifenn_runs'][run]['fem_run']}/fields.h5",
                  "results/picnn/model.pt"}
    return sorted(paths)


def adaptive_inputs(wildcards):
    """An adaptive run's spec, the network where it is a verified IFENN run, and the outputs of
    the run it starts from (run_start)."""
    inputs = {"spec": f"results/adaptive/{wildcards.run}/spec.json"}
    if config["adaptive_runs"][wildcards.run].get("ifenn_run"):
        inputs["model"] = "results/picnn/model.pt"
    return {**inputs, **start_inputs("adaptive", wildcards.run)}


def adaptive_resolution_cases():
    return {case: {"fem_run": e["fem_run"], "fine_fem_run": e["fine_fem_run"], "fem_dir": f"results/fem/{e['fem_run']}",
                   "fine_dir": finer_reference_dir(config, e["fine_fem_run"]),
                   "adaptive_dirs": {run: f"results/adaptive/{run}" for run in e["adaptive_runs"]}}
            for case, e in config.get("adaptive_resolution", {}).items()}


def adaptive_resolution_inputs(wildcards):
    files = []
    for where in adaptive_resolution_cases().values():
        for folder in (where["fem_dir"], where["fine_dir"], *where["adaptive_dirs"].values()):
            files += [f"{folder}/history.csv", f"{folder}/provenance.json", f"{folder}/spec.json"]
        files += [f"{folder}/fields.h5" for folder in where["adaptive_dirs"].values()]
    return files


# The tables results/summary.md renders (ifenn.studies.tables.summary.SECTIONS): those this config produces.
SUMMARY_TABLES = {
    key: path
    for key, path, produced in [
        ("accuracy", "results/tables/accuracy.csv", True),
        ("timing", "results/tables/timing.csv", True),
        ("speed_accuracy", "results/tables/speed_accuracy.csv", config.get("speed_accuracy")),
        ("adaptive_resolution", "results/tables/adaptive_resolution.csv", config.get("adaptive_resolution")),
        ("reference_convergence", "results/tables/reference_convergence.csv", config.get("reference_convergence")),
        ("whole_path", "results/tables/whole_path.csv", config.get("whole_path")),
        ("process_zone", "results/tables/process_zone.csv", PROCESS_ZONE_PAIRS),
        ("error_sources", "results/tables/error_sources.csv", config.get("error_sources")),
        ("stability", "results/tables/stability.csv", config.get("stability")),
        ("phase_field_speed", "results/benchmarks/phase_field_speed.csv", config.get("phase_field_benchmark")),
        ("whole_run_speed", "results/benchmarks/whole_run_speed.csv", config.get("whole_run_benchmark")),
        ("increment_speed", "results/benchmarks/increment_speed.csv", config.get("increment_benchmark")),
        ("network_worth", "results/benchmarks/network_worth.csv", config.get("network_worth")),
    ]
    if produced
}


def specimen_factors(specimen):
    """Per run of a specimen (its fem, ifenn and adaptive runs, in that order): how many copies of
    its scene make the specimen (a half behind a mirror plane: 2)."""
    entry = config["specimens"][specimen]
    fem = list(entry["fem_runs"])
    fem += [config["ifenn_runs"][run]["fem_run"] for run in entry.get("ifenn_runs", [])]
    fem += [config["adaptive_runs"][run]["fem_run"] for run in entry.get("adaptive_runs", [])]
    return [symmetry_factor(config["scenes"][config["fem_runs"][run]["scene"]]) for run in fem]
