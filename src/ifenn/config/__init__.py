"""Configuration: the config is data (config/config.yaml: scenes, load schedules, runs). Every check
happens before any computation, and every error names the key, the value and what is allowed.

- :mod:`~ifenn.config.loading`: YAML merged, the schema checked and its defaults filled;
- :mod:`~ifenn.config.checks`: the checks across keys (a scene's own beside its geometry and material);
- :mod:`~ifenn.config.petsc_names`: PETSc option values checked before a run;
- :mod:`~ifenn.config.specs`: each run resolved into the spec its job reads (spec.json);
- :mod:`~ifenn.config.prefixes`: the runs that start from another run's saved state.
"""

from ifenn.config.loading import ConfigError, deep_merge, load_config, validate_config
from ifenn.config.prefixes import adaptive_shared_prefix, shared_prefix
from ifenn.config.specs import (
    ADAPTIVE_RUN_OVERRIDES,
    IFENN_OPTIONS,
    SWITCH_OVER,
    adaptive_run_spec,
    fem_run_spec,
    finer_reference_dir,
    finer_reference_runs,
    ifenn_run_spec,
    load_values,
    paired_runs,
    schedule_increments,
    speed_accuracy_setups,
    switch_over,
    training_spec,
)
from ifenn.schema import REPO

__all__ = ["ADAPTIVE_RUN_OVERRIDES", "IFENN_OPTIONS", "REPO", "SWITCH_OVER", "ConfigError", "adaptive_run_spec",
           "adaptive_shared_prefix", "deep_merge", "fem_run_spec", "finer_reference_dir", "finer_reference_runs",
           "ifenn_run_spec", "load_config", "load_values", "paired_runs", "schedule_increments", "shared_prefix",
           "speed_accuracy_setups", "switch_over", "training_spec", "validate_config"]
