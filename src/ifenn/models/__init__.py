"""The phase-field model: the one place that knows the degradation function, the crack density and
the driving force. FEM's forms (:mod:`ifenn.fem`), the pixel equation (:mod:`ifenn.pixel_equation`)
and the adaptive mesh (:mod:`ifenn.adaptive`) ask :func:`phase_field_model` for a run's model and
call it; nothing else branches on the model.

Models: ``hybrid-at2`` (:mod:`ifenn.models.hybrid_at2`, the paper's).
"""

from __future__ import annotations

from ifenn.models.hybrid_at2 import HybridAT2

#: the models by name
MODELS = {HybridAT2.name: HybridAT2()}
#: the paper's model, every scene's today
DEFAULT_MODEL = HybridAT2.name


def phase_field_model(material: dict | None = None) -> HybridAT2:
    """The model a run of ``material`` uses (the paper's AT2 with the hybrid split, the one model
    there is: a material names its own once there are several)."""
    return MODELS[DEFAULT_MODEL]
