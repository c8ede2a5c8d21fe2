"""The run specs' types describe every spec the configs build: each spec of the paper and quick
configs reads into its type, and back to the same JSON with every default made explicit."""

from __future__ import annotations

import dataclasses
import json

import pytest

from ifenn.config import adaptive_run_spec, fem_run_spec, ifenn_run_spec, shared_prefix, training_spec
from ifenn.specs import SPEC_TYPES, spec_dict, typed_spec
from ifenn.studies.drivers.stability import cells


def _every_spec(config):
    yield "training", training_spec(config)
    for run in config["fem_runs"]:
        start = shared_prefix(config, run)
        yield "fem", {**fem_run_spec(config, run), **({"start_from": start} if start else {})}
    for run in config["ifenn_runs"]:
        yield "ifenn", ifenn_run_spec(config, run)
    for run in config.get("adaptive_runs", {}):
        yield "adaptive", adaptive_run_spec(config, run)
    for cell in cells(config).values():
        yield cell["method"], cell["spec"]


@pytest.mark.parametrize("which", ["paper", "quick"])
def test_every_spec_the_config_builds_reads_into_its_type(which, paper_config, quick_config):
    config = paper_config if which == "paper" else quick_config
    counts = dict.fromkeys(SPEC_TYPES, 0)
    for kind, spec in _every_spec(config):
        typed = typed_spec(kind, spec)
        whole = spec_dict(typed)
        assert json.loads(json.dumps({k: whole[k] for k in spec})) == json.loads(json.dumps(spec)), (kind, spec.get("name"))
        defaults = {f.name: f.default for f in dataclasses.fields(type(typed)) if f.name not in spec}
        assert all(whole[name] == value for name, value in defaults.items()), (kind, spec.get("name"))
        counts[kind] += 1
    assert all(counts.values()), counts


def test_a_key_the_type_does_not_know_or_a_missing_field_is_refused_by_name(quick_config):
    spec = fem_run_spec(quick_config, "snt1-I")
    with pytest.raises(ValueError, match=r"no field \['stagger_tolerence'\]"):
        typed_spec("fem", {**spec, "stagger_tolerence": 1e-3})
    with pytest.raises(ValueError, match=r"needs \['petsc'\]"):
        typed_spec("fem", {k: v for k, v in spec.items() if k != "petsc"})
    with pytest.raises(ValueError, match="spec kind 'cell'"):
        typed_spec("cell", spec)
    typed = typed_spec("fem", spec)
    assert typed.load == tuple(spec["load"]) and typed.adaptive is None and typed.start_from is None
    with pytest.raises(dataclasses.FrozenInstanceError):
        typed.name = "other"
