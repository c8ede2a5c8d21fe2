"""The PICNN's training settings: defaults, the named presets and their resolution
(:mod:`ifenn.network.training`'s docstring says what each setting does). Free of torch and of the
network's code, so that the config checks resolve a preset without importing either."""

from __future__ import annotations

from ifenn.schema import schema_default

#: H_cap of the config schema (ifenn.history_cap), N/mm^2
DEFAULT_HISTORY_CAP = schema_default("ifenn", "history_cap")

DEFAULT_SETTINGS: dict = {
    "lr": 1e-3,
    "lr_final": None,
    "epochs": 5000,
    "sampling": "full",
    "padding": "zeros",
    "laplacian_padding": "zeros",
    "input_scaling": "none",
    "input_reference": 1.0,
    "input_centre": None,
    "history_cap": DEFAULT_HISTORY_CAP,
    "channels": (1, 24, 24, 24, 1),
    "kernel_size": 5,
    "optimiser": "adam",
    "residual_scaling": "none",
    "residual_scaling_exponent": 1.0,
    "residual_scaling_warmup": 0,
    "tile_size": 46,
    "process_zone_history": None,
    "process_zone_margin": None,
    "process_zone_tiles": None,
    "far_field_tiles": 4,
    "tile_weighting": "count",
    "full_image_epochs": 0,
    "dtype": "float32",
    "log_every": 10,
}

PRESETS: dict[str, dict] = {
    "released": {"lr": 1e-3, "epochs": 5000, "sampling": "full"},
    "text": {"lr": 1e-4, "epochs": 10000, "sampling": "full"},
    "tiles": {
        "lr": 1e-3,
        "lr_final": 1e-5,
        "epochs": 1000,
        "sampling": "tiles",
        "padding": "replicate",
        "laplacian_padding": "replicate",
        "input_scaling": "log",
        "input_reference": 0.01,
        "residual_scaling": "reaction",
        "residual_scaling_exponent": 0.5,
        "tile_size": 30,
        "process_zone_tiles": 6,
        "far_field_tiles": 4,
        "tile_weighting": "count",
        "full_image_epochs": 0,
    },
}


SAMPLINGS = ("full", "tiles")


def resolve_settings(settings: dict | None = None) -> dict:
    """DEFAULT_SETTINGS, overridden by ``settings["preset"]`` (if any), then by ``settings``."""
    settings = dict(settings or {})
    resolved = dict(DEFAULT_SETTINGS)
    preset = settings.pop("preset", None)
    if preset is not None:
        resolved.update(PRESETS[preset])
        resolved["preset"] = preset
    unknown = set(settings) - set(DEFAULT_SETTINGS)
    if unknown:
        raise KeyError(f"unknown PICNN training settings: {sorted(unknown)}")
    resolved.update(settings)
    if resolved["sampling"] not in SAMPLINGS:
        raise KeyError(f"PICNN training setting 'sampling': {resolved['sampling']!r}; allowed: {list(SAMPLINGS)}")
    return resolved
