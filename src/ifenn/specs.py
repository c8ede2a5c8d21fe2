"""The run specs as types: what a FEM, IFENN, adaptive-mesh or training job reads, one frozen
dataclass per kind, every field named with its default.

The config builds each spec (:mod:`ifenn.config.specs`) as a JSON object, written to the run's
spec.json; :func:`typed_spec` reads one into its type and refuses a key the type does not know, so
the types are the list of what a spec holds. Fields whose value is "not used by this run" default
to None (a fixed schedule's ``adaptive``, an unverified run's ``verification``).
"""

from __future__ import annotations

import dataclasses
from typing import Any, ClassVar


@dataclasses.dataclass(frozen=True, kw_only=True)
class FemRunSpec:
    """A FEM run: the scene, its material, the load schedule, the staggering and the solvers."""

    KIND: ClassVar[str] = "fem"
    name: str
    scene_name: str
    scene: dict                      # the config's scene (domain, elements, notches, cut-outs, supports)
    material: dict                   # the scene's material (ifenn.materials.scene_material)
    schedule_name: str
    load: tuple[float, ...] | None = None      # a fixed schedule's prescribed displacements, mm
    adaptive: dict | None = None               # an adaptive schedule's controller
    save_every: int | None = None              # an adaptive schedule's field saving, every N increments
    stagger_max_iterations: int
    stagger_tolerance: float
    linear_solvers: str
    petsc: dict                      # the preset's PETSc options per field
    checkpoint_every: int
    save_fields: tuple[int, ...]
    switch_phi_max: float
    mpi_ranks: int = 1
    start_from: dict | None = None   # the run whose saved state this one starts from (ifenn.config.prefixes)


@dataclasses.dataclass(frozen=True, kw_only=True)
class HybridSettings:
    """The hybrid phase-field step's options (config 'ifenn', per run overridden)."""

    predictor: str
    evaluation: str
    history_cap: float
    smoothing_sigma: float | None
    smoothing_truncate: float
    irreversible: bool
    pixel_padding: str
    inference: str
    process_zone: dict | None = None   # with inference 'process_zone', or a verified run's network
    verification: dict | None = None   # a verified run's check and correction


@dataclasses.dataclass(frozen=True, kw_only=True)
class IfennRunSpec(HybridSettings, FemRunSpec):
    """An IFENN run: its FEM run's spec, the hybrid step's options and the switch-over."""

    KIND: ClassVar[str] = "ifenn"
    fem_run: str
    switch_over: str = "phi_threshold"
    switch_increment: int | None = None


@dataclasses.dataclass(frozen=True, kw_only=True)
class AdaptiveRunSpec(FemRunSpec):
    """A run on the mesh that follows the crack: its FEM run's spec (scene, schedule and staggering
    may be its own), the mesh's settings and, for a verified IFENN run (``ifenn_run``), that run's
    hybrid options."""

    KIND: ClassVar[str] = "adaptive"
    fem_run: str
    adaptive_mesh: dict
    ifenn_run: str | None = None
    predictor: str | None = None
    evaluation: str | None = None
    history_cap: float | None = None
    smoothing_sigma: float | None = None
    smoothing_truncate: float | None = None
    irreversible: bool | None = None
    pixel_padding: str | None = None
    inference: str | None = None
    process_zone: dict | None = None
    verification: dict | None = None


@dataclasses.dataclass(frozen=True, kw_only=True)
class TrainingSpec:
    """The network's training: the FEM run and increments it learns from, the preset and its
    overrides, and the training scene's material and scene (its slits cut the loss's stencil)."""

    KIND: ClassVar[str] = "training"
    training_run: str
    training_increments: tuple[int, ...]
    preset: str
    settings: dict
    seed: int
    threads: int
    material: dict
    scene: dict


SPEC_TYPES = {cls.KIND: cls for cls in (FemRunSpec, IfennRunSpec, AdaptiveRunSpec, TrainingSpec)}
_TUPLES = ("load", "save_fields", "training_increments")


def typed_spec(kind: str, spec: dict) -> Any:
    """The spec of a ``kind`` job (fem, ifenn, adaptive, training) as its type; a key the type does
    not know, or a field without a default that is missing, is refused with its name."""
    if kind not in SPEC_TYPES:
        raise ValueError(f"spec kind '{kind}'; allowed: {sorted(SPEC_TYPES)}")
    cls = SPEC_TYPES[kind]
    names = {f.name for f in dataclasses.fields(cls)}
    unknown = sorted(set(spec) - names)
    if unknown:
        raise ValueError(f"a {kind} spec has no field {unknown}; its fields: {sorted(names)}")
    missing = sorted(f.name for f in dataclasses.fields(cls) if f.name not in spec
                     and f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING)
    if missing:
        raise ValueError(f"a {kind} spec needs {missing}")
    values = {k: tuple(v) if k in _TUPLES and v is not None else v for k, v in spec.items()}
    return cls(**values)


def spec_dict(spec: Any) -> dict:
    """A typed spec as the JSON object of spec.json, every field included (tuples as lists)."""
    return {k: list(v) if isinstance(v, tuple) else v for k, v in dataclasses.asdict(spec).items()}
