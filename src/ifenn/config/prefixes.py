"""Runs whose first increments are another run's: the saved state a FEM or adaptive run can start
from (config ``solver.share_load_prefix``)."""

from __future__ import annotations

from ifenn.config.specs import adaptive_run_spec, fem_run_spec, paired_runs
from ifenn.run_files import spec_hash

#: what may differ between two runs whose first increments are the same computation
PREFIX_FREE_KEYS = ("name", "fem_run", "schedule_name", "load", "save_fields")


def _longest_shared_prefix(spec: dict, others: dict[str, dict]) -> dict | None:
    """The run of ``others`` (name -> spec) whose saved state ``spec`` can start from
    (:func:`shared_prefix`): {'run', 'increment', 'spec_hash'}, or None."""
    if spec.get("load") is None:
        return None
    rest = {k: v for k, v in spec.items() if k not in PREFIX_FREE_KEYS}
    best = None
    for other in sorted(others):
        candidate = others[other]
        if other == spec["name"] or candidate.get("load") is None or (len(candidate["load"]), other) >= (len(spec["load"]), spec["name"]):
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
