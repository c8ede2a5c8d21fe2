"""The numbers the docs quote, rendered from the tables of one workflow run: ``results/summary.md``.

README and docs/ never carry a measured number typed by hand: they point here. Every section is a
table the workflow wrote in the same run (its path is the section's link), with the machine it ran
on (``results/benchmarks/machine_speed.json``) and the date, so a reader sees which numbers belong
together and how fast the machine was. A table the run's config does not produce is left out,
and the summary says so.

Inputs are paths, never the ``results/`` layout: ``tables`` maps a section key of
:data:`SECTIONS` to its CSV.
"""

from __future__ import annotations

import datetime as dt
import json
import os
from dataclasses import dataclass
from pathlib import Path

import pandas as pd

from ifenn.io import atomic_path


@dataclass(frozen=True)
class Section:
    title: str
    what: str                       # one sentence: what the table shows and against what
    columns: tuple[str, ...] = ()   # the columns shown, in order (those present); empty: all


def _section(title: str, what: str, columns: str = "") -> Section:
    return Section(title, what, tuple(columns.split()))


#: one section per table of the DAG, in the order a reader meets them (docs/results.md follows it)
SECTIONS: dict[str, Section] = {
    "accuracy": _section(
        "IFENN against the FEM run it continues",
        "The published hybrid step and its variants against FEM on the same mesh and schedule; errors "
        "after the switch-over are fractions of FEM's peak force.",
        "run fem_run peak_force_rel_error force_l2_rel_error post_switch_rms_error post_switch_max_error "
        "final_force_fraction_fem final_force_fraction_ifenn dissipated_energy_rel_error crack_iou_3"),
    "timing": _section(
        "Seconds per increment over the propagation stage",
        "Wall time of each step of an increment, per run, measured inside the runs of this DAG.",
        "run method increments t_displacement_s t_phase_field_s t_increment_s phase_field_time_vs_fem "
        "increment_time_vs_fem"),
    "speed_accuracy": _section(
        "Speed against accuracy",
        "Every method variant's wall time against its force-curve error versus the converged reference "
        "(finest schedule, converged staggering, adaptive mesh one level finer); `pareto_wall_s` marks the front, "
        "`role` the reference, FEM as published (`baseline`) and the combined runs, `wall_vs_baseline` the wall "
        "over the baseline's.",
        "scene run variant schedule converged role wall_s wall_vs_baseline force_l2_rel_error work_rel_error post_peak_rms "
        "peak_force_rel_error pareto_wall_s"),
    "adaptive_resolution": _section(
        "The displacement mesh that follows the crack",
        "Adaptive runs against the finer reference of the same specimen: peak and post-peak error (%), wall "
        "time against FEM at h from the same DAG, and displacement dofs against the finer mesh's.",
        "case run method fine_reference peak_error_vs_fine_pct post_peak_rms_vs_fine_pct wall_s wall_fem_h_s "
        "dofs_fraction_of_fine remeshes increments_outside_fine"),
    "reference_convergence": _section(
        "Which discretisation is right after the peak",
        "Verified and whole-path IFENN and FEM at h, each against FEM at h and against the finer reference of "
        "the same specimen and schedule (post-peak force RMS over FEM's peak).",
        "case run method fine_reference rms_vs_fem rms_vs_fine peak_force peak_force_fine u_half_drop "
        "u_half_drop_fine closer_to_fine"),
    "whole_path": _section(
        "IFENN over the whole load path",
        "The verified step from the first increment, against FEM of the same scene and schedule, marked "
        "against the targets of config `whole_path`.",
        "run fem_run peak_force_rel_error u_peak_rel_error post_peak_rms_error final_force_fraction_fem "
        "final_force_fraction_ifenn u_half_drop_rel_error meets_all propagation_verify_residual_after_max"),
    "process_zone": _section(
        "Process-zone inference against the full image",
        "Pairs of IFENN runs that differ only in where the network is evaluated.",
        "run full_run force_l2_rel_error phi_max_abs_diff crack_iou evaluated_fraction_mean "
        "t_phase_field_zone_s t_phase_field_full_s"),
    "error_sources": _section(
        "Where the published step's post-switch error comes from",
        "FEM states after the switch-over replayed with one ingredient of the published step changed at "
        "a time; each source is a force difference over FEM's peak.",
        "run source states force_rms force_mean force_max_abs postswitch_rms_error"),
    "stability": _section(
        "The stability sweep",
        "Load step, lc/h and IFENN options; each cell labelled ok, diverged, no load drop, crack path wrong "
        "or peak off.",
        "panel value method cell label peak_force final_force force_l2_rel_error wall_s"),
    "phase_field_speed": _section(
        "The phase-field step, FEM against IFENN",
        "Seconds per phase-field step from each FEM run's switch-over, one core, every method in one "
        "process: the ratios compare, the seconds move with the machine.",
        "run pixels method device t_phase_field_s t_phase_field_median_s verify_residual_after_max "
        "phase_field_speedup_vs_fem"),
    "whole_run_speed": _section(
        "The phase-field step over a whole run",
        "FEM against whole-path IFENN, one process, increments interleaved.",
        "run method device increments t_phase_field_total_s t_increment_total_s phase_field_speedup_vs_fem "
        "increment_speedup_vs_fem"),
    "increment_speed": _section(
        "The increment per displacement solver",
        "Seconds per displacement solve, phase-field step and increment per method and solver preset, "
        "and the force error against the direct solve.",
        "run method displacement_solver t_displacement_s t_phase_field_s t_increment_s "
        "force_rel_error_vs_direct displacement_iterations"),
    "network_worth": _section(
        "What a network is worth to the verified step",
        "Each warm start replayed through the same check and correction on the run's own history images; "
        "every row ends with the same certificate.",
        "run variant cg_iterations t_step_s evaluated_fraction max_certificate speedup_vs_no_network"),
}


def _machine_line(machine: Path | None) -> str:
    if machine is None or not Path(machine).exists():
        return "The machine was not measured in this run (no machine_speed.json)."
    record = json.loads(Path(machine).read_text())
    reference = record.get("reference", {})
    measured = f", measured {record['date']}" if "date" in record else ""
    return (f"Machine: `{record.get('host', '?')}` ({record.get('machine', '?')}{measured}): one MUMPS Cholesky factor + "
            f"solve of snt1's displacement matrix {record['mumps_factor_solve_s']} s, one apply of its kept "
            f"block Cholesky factor {record['kept_factor_apply_ms']} ms (the reference machine: "
            f"{reference.get('mumps_factor_solve_s', '?')} s and {reference.get('kept_factor_apply_ms', '?')} ms). "
            "Seconds compare only on one machine; ratios within one table are the portable numbers.")


def _table_markdown(frame: pd.DataFrame, columns: tuple[str, ...]) -> str:
    shown = [c for c in columns if c in frame.columns] or list(frame.columns)
    return frame[shown].to_markdown(index=False, floatfmt=".4g")


def render_summary(tables: dict[str, str | Path], machine: str | Path | None = None,
                   config_files: list[str] | None = None, date: str | None = None) -> str:
    """The summary page (Markdown) of the tables ``tables`` (section key -> CSV path)."""
    unknown = sorted(set(tables) - set(SECTIONS))
    if unknown:
        raise ValueError(f"no summary section for {unknown}; known: {sorted(SECTIONS)}")
    date = date or dt.datetime.now(dt.UTC).strftime("%Y-%m-%d %H:%M UTC")
    lines = ["# What this run of the workflow measured", "",
             f"Written by the workflow (rule `summary`, `ifenn.studies.tables.summary`) on {date} from the tables "
             "of this run; every number below is in the file its section links to.",
             "", _machine_line(Path(machine) if machine else None), ""]
    if config_files:
        lines += ["Config: " + ", ".join(f"`{os.path.basename(str(f))}`" for f in config_files) + ".", ""]
    missing = [key for key in SECTIONS if key not in tables]
    for key, section in SECTIONS.items():
        if key not in tables:
            continue
        path = Path(tables[key])
        lines += [f"## {section.title}", "", f"[`{path.name}`]({_relative(path)}): "
                  f"{section.what}", ""]
        frame = pd.read_csv(path)
        lines += [_table_markdown(frame, section.columns) if len(frame) else "(no rows)", ""]
    if missing:
        lines += ["Not produced by this run's config: " + ", ".join(f"`{k}`" for k in missing) + ".", ""]
    return "\n".join(lines)


def _relative(path: Path) -> str:
    """A link from results/summary.md to ``path`` (paths under results/ are written relative)."""
    parts = path.parts
    return str(Path(*parts[parts.index("results") + 1:])) if "results" in parts else str(path)


def write_summary(out: str | Path, tables: dict[str, str | Path], machine: str | Path | None = None,
                  config_files: list[str] | None = None) -> None:
    text = render_summary(tables, machine, config_files)
    Path(out).parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(out) as tmp:
        Path(tmp).write_text(text)
