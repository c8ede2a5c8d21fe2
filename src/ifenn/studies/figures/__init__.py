"""Figures (matplotlib, Agg). Each function writes one file atomically and returns nothing:
the paper's (:mod:`~ifenn.studies.figures.paper`) and the workflow's own measurements
(:mod:`~ifenn.studies.figures.methods`)."""

from ifenn.run_files import read_phase_field_maps
from ifenn.studies.figures.methods import (
    ERROR_SOURCE_COLOURS,
    ERROR_SOURCE_LABELS,
    STABILITY_COLOURS,
    adaptive_mesh_figure,
    adaptive_resolution_figure,
    error_sources_figure,
    network_worth_figure,
    reference_convergence_figure,
    specimen_figure,
    speed_accuracy_figure,
    stability_map_figure,
    whole_path_figure,
    whole_run_speed_figure,
)
from ifenn.studies.figures.paper import (
    comparison_figure,
    comparison_levels,
    force_displacement_figure,
    mesh_figure,
    mesh_study_figure,
    phase_field_time_figure,
    training_data_figure,
    training_figure,
    views_3d_figure,
)

__all__ = ["ERROR_SOURCE_COLOURS", "ERROR_SOURCE_LABELS", "STABILITY_COLOURS", "adaptive_mesh_figure", "adaptive_resolution_figure", "comparison_figure", "comparison_levels", "error_sources_figure", "force_displacement_figure", "mesh_figure", "mesh_study_figure", "network_worth_figure", "phase_field_time_figure", "read_phase_field_maps", "reference_convergence_figure", "specimen_figure", "speed_accuracy_figure", "stability_map_figure", "training_data_figure", "training_figure", "views_3d_figure", "whole_path_figure", "whole_run_speed_figure"]
