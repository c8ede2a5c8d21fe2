"""The configuration schema (config/schema.yaml) and its defaults: the bottom of the package's
imports, so that the modules whose classes default to a schema value (the network, the verified
step, the process zone) and the config checks read one source without importing each other."""

from __future__ import annotations

import functools
from pathlib import Path

import yaml

REPO = Path(__file__).resolve().parents[2]
SCHEMA_PATH = REPO / "config" / "schema.yaml"


def schema_defaults(section: str) -> dict:
    """The schema's defaults of one ``$defs`` section (e.g. 'process_zone', 'verification'):
    the classes that take those settings default to them, so each number is written once."""
    return {key: sub["default"] for key, sub in load_schema()["$defs"][section]["properties"].items() if "default" in sub}


def schema_default(*keys: str):
    """The schema's default of a configuration key, e.g. schema_default('ifenn', 'history_cap')."""
    node = load_schema()
    for key in keys:
        node = node["properties"][key]
    return node["default"]


@functools.cache
def load_schema(path: Path = SCHEMA_PATH) -> dict:
    """The config schema, read once per process (treat as read-only)."""
    with open(path) as stream:
        return yaml.safe_load(stream)
