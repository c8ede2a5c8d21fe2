"""Reading the config: YAML files merged in order, NaN and infinity refused, the JSON schema
checked with its defaults filled, then the checks across keys (:mod:`ifenn.config.checks`). Every
error names the key, the value and what is allowed."""

from __future__ import annotations

import copy
import math
from pathlib import Path
from typing import Any

import jsonschema
import yaml

from ifenn.schema import SCHEMA_PATH, load_schema


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
    :mod:`ifenn.config.petsc_names`); the jobs' Snakemake processes skip it, the main one checked."""
    from ifenn.config.checks import semantic_problems
    from ifenn.config.specs import finer_reference_runs

    schema = load_schema(Path(schema_path))
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
    problems = semantic_problems(config, schema, petsc_names)
    if problems:
        raise ConfigError("invalid configuration:\n  " + "\n  ".join(problems))
    return config
