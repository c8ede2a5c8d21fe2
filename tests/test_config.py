"""Bad configuration fails at once with the key, the value and what is allowed."""

import copy

import pytest

from ifenn.config import ConfigError, fem_run_spec, load_values, speed_accuracy_setups, validate_config


def test_paper_config_has_the_seven_runs(paper_config):
    assert set(paper_config["fem_runs"]) >= {"snt1-I", "snt1-II", "snt1-III", "snt2-II", "snt3-II", "sdnt", "adnt"}
    assert len(fem_run_spec(paper_config, "snt1-III")["load"]) == 1500


def test_schedule_values():
    values = load_values([{"increments": 500, "step": 1e-5}, {"increments": 1000, "step": 1e-6}])
    assert len(values) == 1500
    assert values[499] == pytest.approx(5e-3)
    assert values[-1] == pytest.approx(6e-3)


def assert_refused(paper_config, mutate, expected):
    """``mutate`` of the paper config is refused before any compute, the message naming each of ``expected``."""
    config = copy.deepcopy(paper_config)
    mutate(config)
    with pytest.raises(ConfigError) as info:
        validate_config(config)
    for text in expected:
        assert text in str(info.value), str(info.value)


@pytest.mark.parametrize(
    "mutate, expected",
    [
        (lambda c: c["scenes"]["snt1"].update(elements=[0, 200]), ["scenes.snt1.elements[0]", "minimum of 2"]),
        (lambda c: c["material"].update(Gc=-1.0), ["material.Gc", "-1.0"]),
        (lambda c: c["fem_runs"]["sdnt"].update(schedule="IV"), ["fem_runs.sdnt.schedule", "'IV'", "allowed"]),
        (lambda c: c["scenes"]["snt1"]["notches"][0].update(kind="crack"), ["notches[0].kind", "'crack'", "slit"]),
        (lambda c: c["scenes"]["snt1"]["notches"][0].update(end=[0.7, 0.0]), ["notches[0].end", "outside the domain"]),
        (lambda c: c["scenes"]["snt1"]["notches"][0].update(end=[-0.2, 0.1]), ["horizontal or vertical"]),
        (lambda c: c["scenes"]["snt1"]["boundary"]["top"].update(y="fixed"), ["snt1.boundary", "load"]),
        (lambda c: c["fem_runs"]["snt1-I"].update(save_fields=[351]), ["save_fields", "351", "1..350"]),
        (lambda c: c["solver"].update(linear_solvers="fast"), ["solver.linear_solvers", "'fast'", "iterative"]),
        (lambda c: c.update(materials={}), ["Additional properties", "materials"]),
        (lambda c: c["schedules"]["I"][0].update(step=0.0), ["schedules.I[0].step", "0.0"]),
        (lambda c: c["schedules"]["A"]["adaptive"].update(cut=1.5), ["schedules.A.adaptive.cut", "1.5"]),
        (lambda c: c["schedules"]["A"]["adaptive"].update(step_min=1.0e-3), ["schedules.A.adaptive", "step_min <= step_initial"]),
        (lambda c: c["stability"].update(scene="nowhere"), ["stability.scene", "'nowhere'", "allowed"]),
        (lambda c: c["speed_accuracy"]["snt1"].update(reference="snt9"), ["speed_accuracy.snt1.reference", "'snt9'"]),
        (lambda c: c["speed_accuracy"]["snt1"].update(reference="sdnt-adaptive"),
         ["speed_accuracy.snt1.reference", "'sdnt-adaptive'", "a point of the chart"]),
        (lambda c: c["speed_accuracy"]["snt1"].update(reference_method="ifenn"), ["speed_accuracy.snt1.reference_method", "'ifenn'"]),
        (lambda c: c.update(finer_references="coarse"), ["finer_references", "'coarse'"]),
        (lambda c: c.update(device="tpu"), ["device", "'tpu'"]),
        (lambda c: c["adaptive_mesh"].update(linear_solvers="lu"), ["adaptive_mesh.linear_solvers", "'lu'", "allowed"]),
        (lambda c: c["ifenn_runs"]["snt1-I-pz"].update(evaluation="convolution"),
         ["ifenn_runs.snt1-I-pz.inference", "process_zone needs", "'convolution'"]),
        # refused here, not when the mesh is built or PETSc starts
        (lambda c: c["scenes"]["snt1"].update(elements=[200, 100]), ["scenes.snt1.elements", "[200, 100]", "square", "1 : 1"]),
        (lambda c: c["ifenn"].update(switch_phi_max=1.0), ["ifenn.switch_phi_max", "1.0", "maximum"]),
        (lambda c: c["solver"]["linear_solver_presets"]["iterative"]["displacement"].update(pc_type="gamgg"),
         ["solver.linear_solver_presets.iterative.displacement.pc_type", "'gamgg'", "'gamg'"]),
        (lambda c: c["solver"]["linear_solver_presets"]["direct"]["phase_field"].update(pc_factor_mat_solver_type="mumsp"),
         ["linear_solver_presets.direct.phase_field.pc_factor_mat_solver_type", "'mumsp'", "'mumps'"]),
        (lambda c: c["solver"]["linear_solver_presets"]["iterative"]["phase_field"].update(sub_pc_type="iccc"),
         ["iterative.phase_field.sub_pc_type", "'iccc'", "'icc'"]),
        (lambda c: c["solver"]["linear_solver_presets"]["iterative"]["displacement"].update(ksp_rtol="1e-8"),
         ["iterative.displacement.ksp_rtol", "'1e-8'", "positive number"]),
        (lambda c: c["picnn"]["settings"].update(sampling="process_zone"), ["picnn.settings", "sampling", "'process_zone'", "'tiles'"]),
        (lambda c: c["solver"]["linear_solver_presets"]["gamg-reuse"]["displacement"].update(mg_levels_ksp_max_it=0),
         ["gamg-reuse.displacement.mg_levels_ksp_max_it", "positive integer"]),
        (lambda c: c["increment_benchmark"].update(runs=["snt1-II-pz"]),
         ["increment_benchmark.runs", "'snt1-II-pz'", "not a verified IFENN run", "'ifenn-verified'"]),
        (lambda c: c["increment_benchmark"].update(methods=["fem", "ifenn-checked"]), ["increment_benchmark.methods", "'ifenn-checked'"]),
    ],
)
def test_bad_values_name_key_value_and_allowed(paper_config, mutate, expected):
    assert_refused(paper_config, mutate, expected)


def test_defaults_are_filled(paper_config):
    config = copy.deepcopy(paper_config)
    del config["material"]["residual_stiffness"]
    assert validate_config(config)["material"]["residual_stiffness"] == 0.0


def test_adaptive_finer_references_replace_the_speed_accuracy_points(paper_config):
    """Under finer_references: adaptive a finer reference listed as a FEM point of the chart is its
    adaptive run (the run `all` makes); the other points and the reference stay as they are."""
    config = validate_config({**copy.deepcopy(paper_config), "finer_references": "adaptive"})
    for scene, setup in speed_accuracy_setups(config).items():
        raw = paper_config["speed_accuracy"][scene]
        fines = [run for run in raw["fem"] if run.endswith("-fine")]
        assert fines, scene
        assert setup["fem"] == [run for run in raw["fem"] if run not in fines]
        assert setup["adaptive"] == raw.get("adaptive", []) + [f"{run}-adaptive" for run in fines]
        assert all(run in config["adaptive_runs"] for run in setup["adaptive"])
        assert setup["reference"] == raw["reference"]
    uniform = validate_config({**copy.deepcopy(paper_config), "finer_references": "uniform"})
    assert speed_accuracy_setups(uniform) == uniform["speed_accuracy"]


@pytest.mark.parametrize(
    "mutate, expected",
    [
        (lambda c: c["ifenn"].update(switch_over="never"), ["ifenn.switch_over", "'never'", "phi_threshold", "start"]),
        (lambda c: c["ifenn_runs"]["snt1-I-whole"].update(switch_over="first"), ["ifenn_runs.snt1-I-whole.switch_over", "'first'"]),
        (lambda c: c["ifenn_runs"]["snt1-I"].update(switch_over="increment"),
         ["ifenn_runs.snt1-I.switch_increment", "needs the FEM increment", "1..349"]),
        (lambda c: c["ifenn_runs"]["snt1-I"].update(switch_over="increment", switch_increment=350),
         ["ifenn_runs.snt1-I.switch_increment", "350", "allowed 1..349"]),
        (lambda c: c["ifenn_runs"]["snt1-I"].update(switch_increment=100), ["ifenn_runs.snt1-I.switch_increment", "only with switch_over 'increment'"]),
        (lambda c: c["ifenn"].update(switch_increment=100), ["ifenn.switch_increment", "only with switch_over 'increment'"]),
        (lambda c: c["ifenn_runs"]["snt1-I"].update(switch_over="increment", switch_increment=0), ["switch_increment", "minimum of 1"]),
        (lambda c: c["whole_path"]["runs"].append("snt1-I"), ["whole_path.runs[8]", "'snt1-I'", "needs switch_over 'start'"]),
        (lambda c: c["whole_run_benchmark"]["runs"].append("snt9-whole"), ["whole_run_benchmark.runs[3]", "'snt9-whole'", "allowed"]),
        (lambda c: c["whole_run_benchmark"]["runs"].append("snt1-I-whole"), ["whole_run_benchmark.runs[3]", "training run 'snt1-I'"]),
        (lambda c: c["whole_run_benchmark"]["runs"].append("snt1-II-whole"), ["whole_run_benchmark.runs[3]", "share the FEM run"]),
        (lambda c: c["fem_runs"]["snt2-II"].update(mpi_ranks=2), ["whole_run_benchmark.runs[1]", "mpi_ranks 1"]),
        (lambda c: c["whole_path"].update(network_runs=["snt1-I-verified"]), ["whole_path.network_runs[0]", "not in whole_path.runs"]),
    ],
)
def test_bad_switch_over_is_refused_naming_the_key(paper_config, mutate, expected):
    assert_refused(paper_config, mutate, expected)


def test_switch_over_in_the_specs(paper_config):
    """Every spec says its switch-over (the published runs the paper's threshold); whole-path runs
    say 'start'; a given increment is saved by the FEM run."""
    from ifenn.config import ifenn_run_spec

    published = ifenn_run_spec(paper_config, "snt1-II-verified")
    assert published["switch_over"] == "phi_threshold" and published["switch_increment"] is None
    whole = ifenn_run_spec(paper_config, "snt1-II-whole")
    assert whole["switch_over"] == "start" and whole["switch_increment"] is None and whole["verification"]["enabled"]
    assert whole["load"] == fem_run_spec(paper_config, "snt1-II")["load"]
    config = copy.deepcopy(paper_config)
    config["ifenn_runs"]["snt1-I-at-123"] = {"fem_run": "snt1-I", "switch_over": "increment", "switch_increment": 123}
    config = validate_config(config)
    assert ifenn_run_spec(config, "snt1-I-at-123")["switch_increment"] == 123
    assert 123 in fem_run_spec(config, "snt1-I")["save_fields"] and 123 not in fem_run_spec(paper_config, "snt1-I")["save_fields"]


@pytest.mark.parametrize(
    "overlay, key",
    [
        ("material: {lc: .nan}", "material.lc"),
        ("material: {Gc: .inf}", "material.Gc"),
        ("schedules: {I: [{increments: 350, step: .nan}]}", "schedules.I[0].step"),
        ("ifenn: {verification: {enabled: false, tolerance: .nan}}", "ifenn.verification.tolerance"),
        ("scenes: {snt1: {domain: {x: [-.inf, 0.5]}}}", "scenes.snt1.domain.x[0]"),
        ("solver: {linear_solver_presets: {iterative: {displacement: {ksp_rtol: .nan}}}}",
         "solver.linear_solver_presets.iterative.displacement.ksp_rtol"),
        ("ifenn: {history_cap: -.inf}", "ifenn.history_cap"),
    ],
)
def test_non_finite_numbers_are_refused_naming_the_key(paper_config, overlay, key):
    """YAML's .nan and .inf, merged over the paper config as a --configfile overlay would be,
    are refused before any compute wherever they sit: a NaN fails every range comparison."""
    import yaml

    from ifenn.config import deep_merge

    with pytest.raises(ConfigError) as info:
        validate_config(deep_merge(paper_config, yaml.safe_load(overlay)))
    assert f"config key '{key}'" in str(info.value) and "is not a finite number" in str(info.value), str(info.value)


def test_an_adaptive_run_on_a_finer_scene_of_the_same_specimen(paper_config):
    """The converged reference one level finer: an adaptive run may take its FEM run's schedule and
    solvers to another scene that differs in its elements only (a finer pixel grid); a scene of
    another specimen is refused, naming the key."""
    from ifenn.config import adaptive_run_spec

    spec = adaptive_run_spec(paper_config, "snt1-III-conv-finer-adaptive")
    reference = adaptive_run_spec(paper_config, "snt1-III-conv-adaptive")
    assert spec["scene_name"] == "snt1-fine" and spec["scene"]["elements"] == [2 * n for n in reference["scene"]["elements"]]
    assert spec["load"] == reference["load"] and spec["stagger_max_iterations"] == reference["stagger_max_iterations"]
    config = copy.deepcopy(paper_config)
    config["adaptive_runs"]["snt1-III-conv-finer-adaptive"]["scene"] = "sdnt"
    with pytest.raises(ConfigError, match=r"'adaptive_runs.snt1-III-conv-finer-adaptive.scene': 'sdnt' differs .* in \['notches'\]"):
        validate_config(config, petsc_names=False)


def test_an_adaptive_run_may_take_its_own_schedule_and_staggering(paper_config):
    """The combined run on a specimen needs no uniform FEM run of its schedule: the adaptive run sets
    its own schedule and staggering; the verified step's settings come from the IFENN run, its loads
    do not. An unknown schedule is refused, naming the key."""
    from ifenn.config import adaptive_run_spec

    spec = adaptive_run_spec(paper_config, "l-panel-A-conv-adaptive-verified")
    assert spec["schedule_name"] == "l-panel-A" and spec["load"] is None and spec["adaptive"]["u_end"] == 1.0
    assert spec["stagger_max_iterations"] == 50 and spec["verification"]["enabled"] and spec["scene_name"] == "l-panel"
    config = copy.deepcopy(paper_config)
    config["adaptive_runs"]["l-panel-A-conv-adaptive"]["schedule"] = "l-panel-Z"
    with pytest.raises(ConfigError, match=r"'adaptive_runs.l-panel-A-conv-adaptive.schedule': 'l-panel-Z' is not a schedule"):
        validate_config(config, petsc_names=False)
