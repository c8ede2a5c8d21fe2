"""IFENN runs: plain FEM up to the switch-over increment (taken from the FEM reference run,
never recomputed), then the same staggered loop with a pixel-based phase-field step.

When IFENN takes over is the run's ``switch_over`` criterion (config 'ifenn.switch_over',
:data:`ifenn.config.SWITCH_OVER`):

- ``phi_threshold`` (the paper, the default): after the first FEM increment whose max nodal phi
  exceeds ``switch_phi_max``. A scene with a history notch (Borden et al.'s initial H, about
  B Gc / (2 lc) on the notch line) has phi near 1 at the notch from the first increment, so the
  threshold fires at FEM increment 1 and IFENN computes every later increment; the provenance
  says so (``switch_over.fired_at_first_increment``).
- ``increment``: after FEM increment ``switch_increment`` (its state is saved by the FEM run).
- ``start``: from the scene's initial state (u = 0, phi = 0, H = the initial history); IFENN
  computes every increment and needs no FEM state (the whole-path runs).

provenance.json of an IFENN run states which criterion fired and when (``switch_over``).

history.csv of an IFENN run = the FEM columns + t_inference_s + hybrid_active (0 for the
increments copied from the FEM run, 1 for the hybrid ones).
"""

from __future__ import annotations

import logging
import math
from pathlib import Path

from mpi4py import MPI

from ifenn import run_files
from ifenn.device import device_record, network_device

PREDICTORS = ("picnn", "exact_pixel")


def switch_state(fem_dir: str | Path, increment: int | None = None) -> tuple[int, dict | None, list[dict]]:
    """(switch increment, state at its end, FEM history rows 1..switch) of a FEM run. Without
    ``increment`` the switch is the FEM run's phi-threshold increment (-1, the state None and
    all rows if the FEM run never reached the threshold); with it, that increment, whose state
    the FEM run must have saved."""
    fields = Path(fem_dir) / run_files.FIELDS
    switch = int(run_files.fields_attrs(fields)["switch_increment"]) if increment is None else int(increment)
    state = None
    if switch > 0:
        try:
            (state,) = run_files.read_states(fields, [switch])
        except KeyError as error:
            raise KeyError(f"FEM run {fem_dir} did not save increment {switch}: nothing to switch over from ({error})") from None
        state = {key: state[key] for key in run_files.FIELD_KEYS}
        state["phase_field"] = state["phase_field"][:, None]
    history = run_files.read_history(fem_dir)
    rows = history[history.increment <= max(switch, 0)].to_dict("records") if switch > 0 else history.to_dict("records")
    return switch, state, rows


def switch_record(spec: dict, switch: int, rows: list[dict]) -> dict:
    """What provenance.json says about the switch-over: the criterion, the last FEM increment
    (0: none, IFENN from the initial state), the first IFENN increment, u and phi_max there, and
    whether it fired at the first increment (with the reason where it is the history notch)."""
    criterion = spec.get("switch_over", "phi_threshold")
    last = rows[-1] if rows and switch > 0 else None
    record = {"criterion": criterion, "fem_increments": max(switch, 0), "first_ifenn_increment": max(switch, 0) + 1,
              "u_switch": float(last["u"]) if last else 0.0, "phi_max_at_switch": float(last["phi_max"]) if last else 0.0,
              "fired_at_first_increment": switch <= 1}
    if criterion == "phi_threshold":
        record["switch_phi_max"] = spec["switch_phi_max"]
        if switch == 1 and any(n["kind"] == "history" for n in spec["scene"].get("notches", [])):
            record["note"] = ("the scene's history notch holds phi near 1 at the notch from the first increment, so the "
                              "phi threshold fired at FEM increment 1: IFENN computes every later increment")
    elif criterion == "increment":
        record["switch_increment"] = spec["switch_increment"]
    else:
        record["note"] = "IFENN from the scene's initial state: every increment computed by IFENN, no FEM state used"
    return record


def slit_cuts(spec: dict):
    """The stencil links the run's slits cut on its pixel grid (:class:`ifenn.pixels.SlitCuts`),
    for every pixel operator of the run; None where the padding has no pixel equation."""
    from ifenn.pixels import PixelGrid, SlitCuts

    if spec.get("pixel_padding") not in ("replicate", "zeros"):
        return None
    return SlitCuts.for_scene(spec["scene"], PixelGrid.for_scene(spec["scene"]), spec["pixel_padding"])


def verified_step_backend(device) -> str:
    """Which verified step a run on ``device`` takes: 'compiled' on the CPU (the compiled check and
    correction, :mod:`ifenn.hybrid.verification`), 'torch' on a GPU (the whole step on the device,
    :mod:`ifenn.hybrid.device_step`)."""
    from ifenn.device import resolve_device

    return "torch" if resolve_device(device).type == "cuda" else "compiled"


class ScaledHistory:
    """A network inference fed H times ``scale``: the network trained on one material answers the
    pixel equation of another with the same lc / h_px, whose dimensionless form
    (1 + 2 H lc / Gc) phi - (lc / h_px)^2 Lap_px(phi) = 2 H lc / Gc depends on H only through
    H lc / Gc (:func:`network_service`). Everything else is the wrapped inference's."""

    def __init__(self, inference, scale: float):
        self._inference, self._scale = inference, float(scale)

    def __call__(self, history):
        return self._inference(history * self._scale)

    def __getattr__(self, name):
        return getattr(self._inference, name)


def network_service(spec: dict, model_path, h_px: float) -> dict:
    """How the trained network serves this run's material: ``history_scale`` s (the network is fed
    s H, s = (lc / Gc) / (lc_t / Gc_t) for its training material t) and ``fallback`` (None, or why
    the network cannot: a material other than its own at another lc / h_px, for which no scaling
    of H maps the equations onto each other; the verified step then runs without it, the certified
    pixel step). The scene of the network's own material is served as published, at any lc / h_px."""
    served = {"history_scale": 1.0, "fallback": None}
    if spec.get("predictor") != "picnn" or model_path is None:
        return served
    from ifenn.network.picnn import load_picnn

    meta = load_picnn(model_path, "cpu")[1]
    Gc, lc = spec["material"]["Gc"], spec["material"]["lc"]
    Gc_t, lc_t, h_t = float(meta["Gc"]), float(meta["lc"]), float(meta["h_px"])
    if math.isclose(Gc, Gc_t, rel_tol=1e-12) and math.isclose(lc, lc_t, rel_tol=1e-12):
        return served
    if math.isclose(lc / h_px, lc_t / h_t, rel_tol=1e-6):
        return {**served, "history_scale": (lc / Gc) / (lc_t / Gc_t)}
    return {**served, "fallback": f"the network was trained on Gc = {Gc_t:g}, lc = {lc_t:g} at lc/h_px = {lc_t / h_t:.4g}; "
                                  f"this scene has Gc = {Gc:g}, lc = {lc:g} at lc/h_px = {lc / h_px:.4g}"}


def verified_step(spec: dict, h_px: float, warm_starter, warm_start: str, scale: float = 1.0):
    """The verified step of ``spec`` on the CPU (:class:`ifenn.hybrid.verification.VerifiedInference`
    on the run's pixel equation, slits cut, with its ``verification`` settings) around ``warm_starter``
    (the engine whose answer starts the correction; None with ``warm_start='previous'``). ``scale``:
    the network is fed ``scale`` H (another material's H in its own units), so the published cap on
    this run's H is the run's cap / scale."""
    from ifenn.hybrid.verification import VerifiedInference
    from ifenn.pixel_equation.numpy_backend import PixelEquation

    verification = spec["verification"]
    equation = PixelEquation(spec["material"]["Gc"], spec["material"]["lc"], h_px, spec["pixel_padding"], slit_cuts(spec))
    return VerifiedInference(warm_starter, equation, verification["tolerance"], verification["margin_lc"], verification["max_rounds"],
                             verification["solve_fraction"], warm_start, spec["history_cap"] / scale,
                             verification.get("cap_history", False))


def make_inference(spec: dict, model_path: str | Path | None, h_px: float, shape: tuple[int, int] | None = None,
                   device="auto", service: dict | None = None):
    """The pixel phase-field map of a hybrid run: capped H image -> (smoothed) phi image,
    checked and corrected by the pixel equation when ``spec['verification']['enabled']``
    (:mod:`ifenn.hybrid.verification`; on a GPU the same step in torch, :func:`verified_step_backend`).
    ``shape``: the image's, when known (what the network keeps is then allocated now). ``device``:
    where the network runs (:mod:`ifenn.device`). ``service``: :func:`network_service` (computed
    here when not given): H scaled for another material, or the network left out."""
    service = service or network_service(spec, model_path, h_px)
    scale = service["history_scale"]
    verification = spec.get("verification") or {}
    if verification.get("enabled"):
        if spec["predictor"] != "picnn":
            raise ValueError("verification checks the PICNN's prediction: it needs predictor 'picnn'")
        warm_start = "previous" if service["fallback"] else verification["warm_start"]
        Gc, lc = spec["material"]["Gc"], spec["material"]["lc"]
        settings = (verification["tolerance"], verification["margin_lc"], verification["max_rounds"], verification["solve_fraction"],
                    warm_start, spec["history_cap"] / scale, verification.get("cap_history", False))
        if verified_step_backend(device) == "torch":   # the whole step on the device (ifenn.hybrid.device_step)
            from ifenn.device import resolve_device
            from ifenn.hybrid.device_step import DeviceVerifiedInference
            from ifenn.network.picnn import load_picnn
            from ifenn.pixel_equation.torch_backend import TorchPixelEquation

            device = resolve_device(device)
            model = load_picnn(model_path, device, spec["history_cap"])[0] if warm_start != "previous" else None
            equation = TorchPixelEquation(Gc, lc, h_px, spec["pixel_padding"], slit_cuts(spec), device)
            return DeviceVerifiedInference(model, equation, *settings, sigma=spec["smoothing_sigma"], truncate=spec["smoothing_truncate"],
                                           network_tolerance=verification.get("network_tolerance"), input_scale=scale)
        network = None
        if warm_start != "previous":
            # the network only warm-starts a certified correction: how often it is asked is its own setting
            zone = spec["process_zone"]
            if verification.get("network_tolerance") is not None:
                zone = {**zone, "tolerance": verification["network_tolerance"]}
            network = network_inference({**spec, "process_zone": zone}, model_path, h_px, shape, device, scale)
        return verified_step(spec, h_px, network, warm_start, scale)
    if service["fallback"]:
        raise ValueError(f"the network cannot serve this scene's material ({service['fallback']}): run it verified "
                         "(the certified pixel step) or with predictor exact_pixel")
    return network_inference(spec, model_path, h_px, shape, device, scale)


def pixel_phase_field(spec: dict, problem, model_path, comm=MPI.COMM_WORLD, device="auto", service: dict | None = None):
    """The hybrid phase-field step of ``spec`` on ``problem``: its inference (:func:`make_inference`,
    on rank 0), checked and corrected by the pixel equation where ``verification.enabled``."""
    from ifenn.hybrid.pixel_step import PixelPhaseField

    verified = bool((spec.get("verification") or {}).get("enabled"))
    service = service or network_service(spec, model_path, problem.pixels.h_px)
    inference = make_inference(spec, model_path, problem.pixels.h_px, problem.pixels.shape, device, service) if comm.rank == 0 else None
    # the published cap is on the network's input: on another material's H it is cap / scale
    return PixelPhaseField(problem, inference, spec["predictor"] + ("-verified" if verified else ""),
                           spec["history_cap"] / service["history_scale"], spec["irreversible"], verified)


def network_inference(spec: dict, model_path, h_px: float, shape, device="auto", scale: float = 1.0):
    """The network's (or the exact pixel solve's) inference; ``scale``: the network is fed
    ``scale`` H (:class:`ScaledHistory`, another material's H in its own units)."""
    from ifenn.hybrid.process_zone import FullInference, ProcessZoneInference

    sigma, truncate = spec["smoothing_sigma"], spec["smoothing_truncate"]
    if spec["predictor"] == "picnn":
        from ifenn.device import resolve_device
        from ifenn.network.orbit import make_evaluator
        from ifenn.network.picnn import load_picnn

        device = resolve_device(device)
        model, _ = load_picnn(model_path, device, spec["history_cap"])   # the run owns the cap (in the network's units)
        # the orbit sums are a CPU kernel; on a GPU the network's own convolutions
        evaluator = make_evaluator(model, spec.get("evaluation", "orbit") if device.type == "cpu" else "convolution")
        if spec.get("inference", "full") == "process_zone":
            zone = spec["process_zone"]
            # its local phase field 2 H / (Gc/lc + 2 H) on the scaled H: Gc/lc scaled alike
            inference = ProcessZoneInference(evaluator, sigma, truncate, zone["tolerance"], zone["refresh_every"], zone["full_fraction"],
                                             local_scale=scale * spec["material"]["Gc"] / spec["material"]["lc"], shape=shape)
        else:
            if shape is not None:
                evaluator.prepare(shape)
            inference = FullInference(evaluator.predict, sigma, truncate, evaluator.kernel)
        return inference if scale == 1.0 else ScaledHistory(inference, scale)
    if spec["predictor"] == "exact_pixel":
        from ifenn.pixel_equation.numpy_backend import solve_pixel_equation

        if spec.get("inference", "full") != "full":
            raise ValueError("inference 'process_zone' needs the local PICNN; the exact pixel solve is global: use 'full'")
        Gc, lc = spec["material"]["Gc"], spec["material"]["lc"]
        cuts = slit_cuts(spec)
        return FullInference(lambda history: solve_pixel_equation(history, Gc, lc, h_px, spec["pixel_padding"], cuts=cuts), sigma, truncate)
    raise ValueError(f"ifenn predictor '{spec['predictor']}' is unknown; allowed: {PREDICTORS}")


def run_ifenn(spec: dict, mesh_path, fem_dir, model_path, out_dir, progress: bool = True, device="auto") -> list[dict]:
    """Continue the FEM run in ``fem_dir`` from its switch-over increment with IFENN (by the
    spec's ``switch_over`` criterion, module doc); with ``switch_over: start`` from the scene's
    initial state, and ``fem_dir`` is not read (it may be None). One process at a time writes
    ``out_dir`` (:func:`ifenn.run_files.exclusive_writer`). ``device``: where the network runs
    (:mod:`ifenn.device`; recorded in provenance.json)."""
    from ifenn.run_files import exclusive_writer

    with exclusive_writer(out_dir, MPI.COMM_WORLD):
        return ifenn_run(spec, mesh_path, fem_dir, model_path, out_dir, progress, device).run()


def ifenn_run(spec: dict, mesh_path, fem_dir, model_path, out_dir, progress: bool = True, device="auto"):
    """The IFENN run of :func:`run_ifenn`, set up at its start (the FEM switch-over state, or the
    initial state), not started (a :class:`ifenn.fem.solver.StaggeredRun`); the caller holds
    ``out_dir``'s lock."""
    from ifenn.fem.mesh import read_dolfinx_mesh
    from ifenn.fem.problem import FractureProblem
    from ifenn.fem.solver import StaggeredRun

    comm = MPI.COMM_WORLD
    criterion = spec.get("switch_over", "phi_threshold")
    if criterion == "start":
        switch, state, rows = 0, None, []
    else:
        increment = spec["switch_increment"] if criterion == "increment" else None
        switch, state, rows = switch_state(fem_dir, increment) if comm.rank == 0 else (None, None, None)
        switch = comm.bcast(switch, root=0)
        if switch <= 0:
            raise RuntimeError(f"FEM run {fem_dir} never reached phi_max > {spec['switch_phi_max']}: nothing for IFENN to take over")
    record = comm.bcast(switch_record(spec, switch, rows) if comm.rank == 0 else None, root=0)
    domain = read_dolfinx_mesh(mesh_path, comm)
    problem = FractureProblem(domain, spec["scene"], spec["material"], spec["petsc"], comm)
    device = network_device(spec, device)
    service = network_service(spec, model_path, problem.pixels.h_px)
    step = pixel_phase_field(spec, problem, model_path, comm, device, service)
    start = {"increment": switch, "state": state, "rows": rows} if switch > 0 else None
    if service["fallback"]:
        logging.getLogger(__name__).warning("%s: the network is left out, the certified pixel step runs: %s", spec["name"], service["fallback"])
    return StaggeredRun(problem, step, spec, out_dir, progress, start=start, row_constants={"hybrid_active": 1},
                        provenance_extra={"switch_over": record, "network_material": service, **device_record(device)})
