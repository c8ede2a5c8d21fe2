"""What a network can be worth to the verified step: the correction's work and the
step's time for each warm start, on the history images of the verified loop itself, and the
bounds no network of that role can beat.

The loop: a verified IFENN run (the workflow's ``{run}-verified`` spec, from its FEM run's
switch-over state, ``increments`` increments of propagation) records the history image its
phase-field step receives at every increment. Every variant then replays that sequence, from the
same start phi, through the same check and correction (:class:`ifenn.hybrid.verification.
VerifiedInference`, same tolerance, so the same certificate); only the warm start differs. The
sequence is the loop's: the variants' phi agree within the tolerance, so the history they would
have produced in the loop differs from it by the tolerance's effect on the displacement, which is
what the certificate allows every variant alike.

Variants (column ``variant``):

* ``no network``: the last verified phi (warm start ``previous``).
* ``paper's network``: the workflow's verified step (warm start ``increment``: the change of the
  trained PICNN's answer added to the last verified phi, the network asked again only where the local
  phi moved by ``network_tolerance``; its time included).
* ``paper's network, whole image``: the same, the network asked on the whole image every step (its
  compiled orbit kernel): what a network on the whole image costs here.
* ``change network``: a network trained for this job (:mod:`ifenn.network.change_net`: fed the
  check's residual of the last verified phi under the new history and that phi, it answers the
  change; trained with the check's own norm on the first half of the first run's loop, the states
  of the "no network" replay), on the whole image every step, its time included.
* ``extrapolation``: no network, the last verified phi plus its last change (phi_k + (phi_k -
  phi_k-1)): what predicting the change costs nothing to try.
* ``oracle in the zone``: the exact pixel solution of the new history, taken where the paper's
  network would be asked (the pixels whose local phi moved by ``network_tolerance``, grown by twice
  the network's reach and the smoothing radius), the last verified phi elsewhere, at no cost: the
  best any network asked there can do. ``oracle in the zone 0.01`` / ``0.001``: on the wider zones
  of those tolerances (``evaluated_fraction``: the share of the image).
* ``oracle everywhere``: the exact solution on the whole image at no cost: the check alone. A
  network on the whole image pays only if it costs less than what this saves on ``no network``.

The oracles' exact solutions are computed outside the timed step (``t_network`` 0). The step's
time is ``t_check + t_correction + t_network`` of :class:`VerifiedInference`; the correction's
load-independent cost is ``solve_work`` (CG iterations x box pixels / image pixels).
"""

from __future__ import annotations

import copy
import tempfile
from pathlib import Path

import numpy as np
import pandas as pd

#: the oracle asked on wider zones: the local phi's tolerance of the paper's zone (network_tolerance), then finer
ORACLE_ZONE_TOLERANCES = (None, 1e-2, 1e-3)
VARIANTS = ("no network", "paper's network", "paper's network, whole image", "change network", "extrapolation",
            *(f"oracle in the zone{'' if t is None else f' {t:g}'}" for t in ORACLE_ZONE_TOLERANCES), "oracle everywhere")
#: the change network's training (ifenn.network.change_net.train_change_net): on the first run's loop, its first half
CHANGE_NET_TRAINING = {"channels": (2, 8, 8, 1), "epochs": 300, "crop": 64, "crops_per_state": 2, "lr": 3e-3, "seed": 0}


class _Recorder:
    """Stands for a verified step in the loop, records the (uncapped) history images it is given
    and the phi it starts from."""

    def __init__(self, inner):
        self.inner, self.images, self.start = inner, [], None

    def start_from(self, phi):
        self.start = np.array(phi, dtype=np.float64)
        self.inner.start_from(phi)

    def __call__(self, history):
        self.images.append(np.array(history, dtype=np.float64))
        return self.inner(history)

    def __getattr__(self, name):
        return getattr(self.inner, name)


def record_loop(spec: dict, mesh_path: Path, fem_dir: Path, model_path: Path, increments: int, work: Path) -> tuple[np.ndarray, list]:
    """(start phi, history images) of ``increments`` increments of the verified run ``spec`` from
    its FEM run's switch-over state (the step itself warm-started from the last verified phi)."""
    from ifenn.fem.mesh import read_dolfinx_mesh
    from ifenn.fem.problem import FractureProblem
    from ifenn.fem.solver import StaggeredRun
    from ifenn.hybrid.runs import pixel_phase_field, switch_state

    switch, state, rows = switch_state(fem_dir)
    spec = copy.deepcopy(spec)
    spec.update(name=f"{spec['name']}-recorded", load=spec["load"][: switch + increments], save_fields=[], checkpoint_every=10**6)
    spec["verification"] = {**spec["verification"], "enabled": True, "warm_start": "previous"}
    problem = FractureProblem(read_dolfinx_mesh(mesh_path), spec["scene"], spec["material"], spec["petsc"])
    step = pixel_phase_field(spec, problem, model_path, device="cpu")
    step.inference = recorder = _Recorder(step.inference)
    StaggeredRun(problem, step, spec, work / spec["name"], progress=False, start={"increment": switch, "state": state, "rows": rows},
                 row_constants={"hybrid_active": 1}).run()
    return recorder.start, recorder.images


class _Oracle:
    """A stand-in network (warm start ``network``) answering with given images at no cost;
    ``zone``: only where the paper's network would be asked (else the last answer stays)."""

    kernel = ""

    def __init__(self, exact: list, zone_of=None):
        self.exact, self.zone_of, self.k, self.last = iter(exact), zone_of, 0, None
        self.t_network, self.evaluated_fraction = 0.0, 0.0

    def __call__(self, capped):
        exact = next(self.exact)
        if self.zone_of is None or self.last is None:
            self.last = exact.copy()
            self.evaluated_fraction = 1.0
            return exact
        zone = self.zone_of(capped)
        self.last[zone] = exact[zone]
        self.evaluated_fraction = float(zone.mean())
        return self.last.copy()


class _Extrapolation:
    """A stand-in network (warm start ``increment``) whose change between calls is the verified
    phi's last change: its answer is the verified phi of the call before (``verified.phi``)."""

    kernel = ""

    def __init__(self):
        self.verified, self.t_network, self.evaluated_fraction = None, 0.0, 0.0

    def __call__(self, capped):
        phi = self.verified.phi
        return np.zeros(capped.shape) if phi is None else phi.copy()


class _Zone:
    """The pixels where the paper's network is asked again (ifenn.hybrid.process_zone): local phi
    moved by ``tolerance`` since it was last asked there, grown by ``radius``."""

    def __init__(self, tolerance: float, local_scale: float, radius: int):
        self.tolerance, self.local_scale, self.radius, self.reference = tolerance, local_scale, radius, None

    def __call__(self, capped: np.ndarray) -> np.ndarray:
        import scipy.ndimage

        local = 2.0 * capped / (self.local_scale + 2.0 * capped)
        if self.reference is None:
            self.reference = local
            return np.ones(capped.shape, bool)
        moved = np.abs(local - self.reference) > self.tolerance
        self.reference = np.where(moved, local, self.reference)
        return scipy.ndimage.maximum_filter(moved, size=2 * self.radius + 1, mode="constant")


def replay(spec: dict, model_path: Path, h_px: float, start: np.ndarray, images: list, variant: str, exact: list | None = None,
           change_net=None, verified_phis: list | None = None) -> pd.DataFrame:
    """Per increment: the correction's CG iterations and work, the step's times and certificate, for
    ``variant`` on the recorded sequence (``exact``: the exact pixel solutions, for the oracles;
    ``change_net``: the trained :class:`ifenn.network.change_net.ChangeNet`). ``verified_phis``: a
    list that receives the verified phi of every step."""
    from ifenn.hybrid.runs import network_inference, slit_cuts, verified_step

    verification = spec["verification"]
    Gc, lc = spec["material"]["Gc"], spec["material"]["lc"]
    if variant == "no network":
        step = verified_step(spec, h_px, None, "previous")
    elif variant.startswith("paper's network"):
        if variant == "paper's network":
            run = {**spec, "process_zone": {**spec["process_zone"], "tolerance": verification["network_tolerance"]}}
        else:
            run = {**spec, "inference": "full", "evaluation": "orbit"}
        step = verified_step(spec, h_px, network_inference(run, model_path, h_px, start.shape, "cpu"), "increment")
    elif variant in ("change network", "extrapolation"):
        if variant == "change network":
            from ifenn.network.change_net import ChangeNetWarmStart

            network = ChangeNetWarmStart(change_net, Gc, lc, h_px, spec["pixel_padding"], slit_cuts(spec))
        else:
            network = _Extrapolation()
        step = verified_step(spec, h_px, network, "increment")
        network.verified = step
    else:
        zone_of = None
        if variant.startswith("oracle in the zone"):
            reach = 8  # the default network's (4 layers of 5 x 5 kernels)
            sigma = spec["smoothing_sigma"]
            radius = 2 * reach + (int(spec["smoothing_truncate"] * sigma + 0.5) if sigma else 0)
            tolerance = variant.removeprefix("oracle in the zone").strip()
            zone_of = _Zone(float(tolerance) if tolerance else verification["network_tolerance"], Gc / lc, radius)
        step = verified_step(spec, h_px, _Oracle(exact, zone_of), "network")
    step.start_from(start)
    rows = []
    for k, image in enumerate(images):
        phi = step(image)
        if verified_phis is not None:
            verified_phis.append(np.array(phi))
        rows.append({"increment": k + 1, "cg_iterations": step.solve_iterations, "solve_work": step.solve_work,
                     "t_check_s": step.t_check, "t_correction_s": step.t_correction, "t_network_s": step.t_network,
                     "t_step_s": step.t_check + step.t_correction + step.t_network, "residual_before": step.residual_before,
                     "residual_after": step.residual_after, "evaluated_fraction": step.evaluated_fraction})
    return pd.DataFrame(rows).assign(variant=variant)


def exact_solutions(spec: dict, h_px: float, images: list) -> list:
    """The exact pixel solution of each image's equation (capped as the step caps it)."""
    from ifenn.hybrid.runs import slit_cuts
    from ifenn.pixel_equation.numpy_backend import solve_pixel_equation

    Gc, lc = spec["material"]["Gc"], spec["material"]["lc"]
    cap = spec["history_cap"] if spec["verification"].get("cap_history", False) else np.inf
    cuts = slit_cuts(spec)
    return [solve_pixel_equation(np.minimum(image, cap), Gc, lc, h_px, spec["pixel_padding"], rtol=1e-12, cuts=cuts) for image in images]


def _train_change_net(spec: dict, h_px: float, start: np.ndarray, images: list, phis: list, cuts):
    """The change network, trained on the first half of this loop's states (H_k, the verified phi
    before it), taken from the "no network" replay (``phis``: its verified phi per step)."""
    from ifenn.network.change_net import train_change_net

    if len(phis) != len(images):
        raise ValueError("the change network trains on the 'no network' replay's states: list that variant before it")
    cap = spec["history_cap"] if spec["verification"].get("cap_history", False) else np.inf
    before = [start, *phis[:-1]]
    half = max(1, len(images) // 2)
    states = [(np.minimum(images[k], cap), before[k]) for k in range(half)]
    Gc, lc = spec["material"]["Gc"], spec["material"]["lc"]
    model, log = train_change_net(states, h_px, Gc, lc, spec["pixel_padding"], cuts, **CHANGE_NET_TRAINING)
    return model, {"run": spec["name"], "wall_s": log["wall_s"], "loss": log["loss"]}


def network_worth(specs: list[dict], inputs: dict, model_path: str | Path, increments: int, variants=VARIANTS) -> tuple[pd.DataFrame, pd.DataFrame]:
    """(summary per run and variant, rows per increment) of :func:`replay` on each run's recorded
    loop; ``inputs``: per run name its scene's ``mesh`` and its FEM run's ``fem_dir``."""
    from ifenn.hybrid.runs import slit_cuts
    from ifenn.pixels import PixelGrid

    tables, change_net, training = [], None, {}
    for spec in specs:
        with tempfile.TemporaryDirectory() as tmp:
            start, images = record_loop(spec, Path(inputs[spec["name"]]["mesh"]), Path(inputs[spec["name"]]["fem_dir"]),
                                        Path(model_path), increments, Path(tmp))
        h_px = PixelGrid.for_scene(spec["scene"]).h_px
        exact = exact_solutions(spec, h_px, images) if any(v.startswith("oracle") for v in variants) else None
        phis: list = []
        for variant in variants:
            if variant == "change network" and change_net is None:   # trained on this (the first) run's loop
                change_net, training = _train_change_net(spec, h_px, start, images, phis, slit_cuts(spec))
            table = replay(spec, Path(model_path), h_px, start, images, variant, exact, change_net,
                           phis if variant == "no network" else None)
            if variant == "change network":
                table = table.assign(training_run=training["run"], training_wall_s=training["wall_s"])
            tables.append(table.assign(run=spec["name"], pixels=start.size))
    rows = pd.concat(tables, ignore_index=True)
    later = rows[rows.increment > 1]   # the first step checks a cold start
    summary = later.groupby(["run", "variant"], sort=False).agg(
        pixels=("pixels", "first"), increments=("increment", "size"), cg_iterations=("cg_iterations", "mean"),
        solve_work=("solve_work", "mean"), t_step_s=("t_step_s", "median"), t_network_s=("t_network_s", "median"),
        t_check_s=("t_check_s", "median"), t_correction_s=("t_correction_s", "median"),
        evaluated_fraction=("evaluated_fraction", "mean"), max_certificate=("residual_after", "max")).reset_index()
    baseline = summary[summary.variant == "no network"].set_index("run").t_step_s
    summary["speedup_vs_no_network"] = summary.run.map(baseline) / summary.t_step_s
    return summary, rows
