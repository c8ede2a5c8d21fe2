"""Where the post-switch error of IFENN comes from: each source replayed on the same FEM states.

Method ("replay on the same FEM states"). For every FEM state saved after the switch-over
increment k_s (fields.h5 groups ``increment_XXXXXX``, k > k_s: prescribed displacement u_k, the
displacement field, the history H_k and the Gauss-point phase field phi_FEM,k, all as FEM's
single-pass staggering left them), the phase-field step is replaced by each variant, on the SAME
history H_k:

  ``fem``               FEM's own phi_k (the Q1 solve of the phase-field equation with H_k);
  ``exact_uncapped``    the exact solution of the pixel equation (pixel_equation.numpy_backend.solve_pixel_equation,
                        the run's ``pixel_padding``) with H_k uncapped;
  ``exact``             the same with min(H_k, history_cap), the network's input;
  ``network_raw``       the trained PICNN on min(H_k, history_cap), no smoothing;
  ``network_smoothed``  the published step: the PICNN + Gaussian smoothing (the run's
                        smoothing_sigma / smoothing_truncate; full-image inference);
  ``published``         max(phi_FEM at the switch-over increment, network_smoothed): what the
                        published step's irreversibility phi_gp = max(phi_gp, new) keeps at least
                        (the IFENN run starts from FEM's state at the switch-over);
  ``fem_one_more_pass`` one more staggered pass at u_k from the state (solve u with phi_k,
                        H = max(H_k, psi0+(u)), FEM phase-field solve);
  ``fem_converged``     staggered passes at u_k until max|delta phi| < the run's
                        stagger_tolerance or ``stagger_max_iterations``.

Irreversibility: each variant's phi is used as it comes, phi_gp = new phi, except ``published``.
The published step takes max(phi_gp of the previous increment, new); in a replay the previous
increment is FEM's, not IFENN's, and a max with it would hide what the variant itself does. The one
floor that the IFENN run is sure to carry is FEM's phi at the switch-over (its starting state), so
``published`` applies that one (the run's own later maxima are not known here, so it is a lower
bound of the run's phi). The staggering variants keep H irreversible: H = max(H_k, psi0+); H_{k-1}
is not saved, H_k stands for it.

For every variant and state: max and mean |phi - phi_FEM| over the pixels (= Gauss points), max
phi, the weakest point of the crack (``crack_band_min``: the minimum, over the pixels where
phi_FEM >= ``crack_phi``, of the largest phi within lc of that pixel: the largest phi across the
band at its weakest point), and the reaction force of ONE equilibrium solve at u_k with that phi
(N/mm), also for ``fem`` (so all forces come from the same procedure). Forces are reported as
(F_variant - F_fem) / F_peak,FEM and F_variant / F_peak,FEM.

Attribution (per state, force differences / FEM peak; phi differences between the two variants):

  pixel      = exact_uncapped - fem               the pixel equation against the Q1 FEM solve
  cap        = exact - exact_uncapped             the history cap
  network    = network_raw - exact                the network against the exact pixel solve
  smoothing  = network_smoothed - network_raw     the Gaussian smoothing
  irreversibility = published - network_smoothed  the max with FEM's phi at the switch-over
  published_step = published - fem                = pixel + cap + network + smoothing + irreversibility
                                                    (exactly, per state)
  staggering = fem_converged - fem                single pass against converged staggering (FEM step)

summarised over the replayed states by the RMS, the signed mean (additive: the four means sum to
the published step's) and the largest |difference|. For context each run's table rows also carry
the whole-run post-switch figures of the published IFENN run against FEM (the formula of
tools/postswitch.py): RMS over the hybrid increments of (|F_IFENN| - |F_FEM| interpolated at the
same u) / FEM peak, the largest such error, and the final forces / FEM peak.

Units: forces N per mm of thickness, displacements mm, H N/mm^2; every ``force_*`` and
``postswitch_*`` column is a fraction of the FEM peak force, phi columns are dimensionless.
Serial (one process); the package takes paths and knows nothing of Snakemake.
"""

from __future__ import annotations

import copy
import logging
import time
from pathlib import Path

import numpy as np
import pandas as pd
import scipy.ndimage

from ifenn import run_files
from ifenn.hybrid.runs import switch_state

log = logging.getLogger(__name__)

VARIANTS = ("fem", "exact_uncapped", "exact", "network_raw", "network_smoothed", "published", "fem_one_more_pass",
            "fem_converged")
#: source -> (from variant, to variant): the source's contribution is to - from
SOURCES = {
    "pixel": ("fem", "exact_uncapped"),
    "cap": ("exact_uncapped", "exact"),
    "network": ("exact", "network_raw"),
    "smoothing": ("network_raw", "network_smoothed"),
    "irreversibility": ("network_smoothed", "published"),
    "published_step": ("fem", "published"),
    "staggering": ("fem", "fem_converged"),
}
#: the sources whose sum is the published step's (telescoping, per state)
PUBLISHED_PARTS = ("pixel", "cap", "network", "smoothing", "irreversibility")


# --------------------------------------------------------------------------- inputs
def saved_states(fields_path: str | Path, after: int | None = None) -> tuple[int, dict, list[dict]]:
    """(switch increment, root attrs, states) of a FEM run's fields.h5. A state is a dict with
    ``increment``, ``u`` (mm), ``history`` and ``phase_field_gp`` pixel maps (ny_px, nx_px),
    nodal ``phase_field`` (n_nodes,) and ``displacement`` (n_nodes, 2) in mesh-file order; only
    increments > ``after`` (default: the switch increment), ascending."""
    attrs = run_files.fields_attrs(fields_path)
    switch = int(attrs["switch_increment"])
    return switch, attrs, run_files.read_states(fields_path, after=switch if after is None else after)


def postswitch_error(ifenn_history: pd.DataFrame, fem_history: pd.DataFrame) -> dict:
    """The whole-run post-switch figures of an IFENN run against its FEM run (tools/postswitch.py):
    RMS and largest |error| over the hybrid increments (u within FEM's range) of |F_IFENN| - |F_FEM|
    interpolated linearly at the same u (clamped at the ends), over the FEM peak; final forces over
    the FEM peak. Fractions, not percent."""
    u_fem, f_fem = fem_history.u.to_numpy(), np.abs(fem_history.reaction_force.to_numpy())
    peak = float(f_fem.max())
    post = ifenn_history[(ifenn_history.hybrid_active == 1) & (ifenn_history.u <= u_fem[-1] + 1e-15)]
    errors = np.abs(post.reaction_force.to_numpy()) - np.interp(post.u.to_numpy(), u_fem, f_fem)
    return {
        "fem_peak_force": peak,
        "u_switch": float(post.u.iloc[0]) if len(post) else np.nan,
        "postswitch_increments": len(post),
        "postswitch_rms_error": float(np.sqrt(np.mean(errors**2)) / peak) if len(post) else np.nan,
        "postswitch_max_error": float(np.abs(errors).max() / peak) if len(post) else np.nan,
        "final_force_ifenn": float(abs(ifenn_history.reaction_force.iloc[-1]) / peak),
        "final_force_fem": float(f_fem[-1] / peak),
    }


def crack_band_min(phi: np.ndarray, crack: np.ndarray, radius_px: int) -> float:
    """min over the pixels of ``crack`` (bool map) of the largest ``phi`` within ``radius_px``
    pixels (a disk): the largest phi across the band at the crack's weakest point; nan without a crack."""
    if not crack.any():
        return float("nan")
    r = np.arange(-radius_px, radius_px + 1)
    disk = r[:, None] ** 2 + r[None, :] ** 2 <= radius_px**2
    return float(scipy.ndimage.maximum_filter(phi, footprint=disk, mode="nearest")[crack].min())


# --------------------------------------------------------------------------- replay
class Replay:
    """The problem of one IFENN run, set up once, replaying phase-field variants on FEM states.

    ``spec``: the IFENN run's resolved description (config.ifenn_run_spec, its spec.json);
    ``mesh_path``: the scene's dolfinx mesh (XDMF); ``model_path``: the trained PICNN (None: the
    network variants and the sources that need them are left out);
    ``stagger_max_iterations``: cap of the converged staggering; ``crack_phi``: where FEM's
    crack is formed (phi_FEM >= this), for ``crack_band_min``.
    """

    def __init__(self, spec: dict, mesh_path, model_path, stagger_max_iterations: int = 50, crack_phi: float = 0.95,
                 device="auto"):
        from mpi4py import MPI

        from ifenn.fem.mesh import read_dolfinx_mesh
        from ifenn.fem.phase_field import FEMPhaseField
        from ifenn.fem.problem import FractureProblem
        from ifenn.fem.solver import NodalMap
        from ifenn.hybrid.runs import make_inference, slit_cuts

        self.spec = spec
        self.cuts = slit_cuts(spec)
        self.material = spec["material"]
        self.stagger_max_iterations, self.crack_phi = int(stagger_max_iterations), float(crack_phi)
        domain = read_dolfinx_mesh(mesh_path, MPI.COMM_SELF)
        self.problem = FractureProblem(domain, spec["scene"], self.material, spec["petsc"], MPI.COMM_SELF)
        self.h_px = self.problem.pixels.h_px
        self.band_radius_px = max(1, int(np.ceil(self.material["lc"] / self.h_px)))
        self.u_map, self.phi_map = NodalMap(self.problem.V), NodalMap(self.problem.W)
        self.fem_step = FEMPhaseField(self.problem, spec["petsc"]["phase_field"])
        # the published step, full image (process-zone inference reproduces it within its tolerance)
        published = {**copy.deepcopy(spec), "inference": "full"}
        shape = self.problem.pixels.shape
        self.network_smoothed = self.network_raw = None
        if model_path is not None:
            self.network_smoothed = make_inference(published, model_path, self.h_px, shape, device)
            self.network_raw = make_inference({**published, "smoothing_sigma": None}, model_path, self.h_px, shape, device)

    # ----------------------------------------------------------------- variants
    def exact(self, history: np.ndarray) -> np.ndarray:
        """Exact pixel phase field for a history image (pass it capped or not)."""
        from ifenn.pixel_equation.numpy_backend import solve_pixel_equation

        return solve_pixel_equation(history, self.material["Gc"], self.material["lc"], self.h_px, self.spec["pixel_padding"],
                                    maxiter=5000, cuts=self.cuts)

    def capped(self, history: np.ndarray) -> np.ndarray:
        return np.clip(history, 0.0, self.spec["history_cap"])

    def _set_state(self, state: dict) -> None:
        p = self.problem
        self.u_map.scatter(state["displacement"], p.displacement)
        self.phi_map.scatter(state["phase_field"], p.phase_field)
        p.gauss_points_from_pixels(state["phase_field_gp"], p.phase_field_gp)
        p.gauss_points_from_pixels(state["history"], p.history)
        p.history_previous.x.array[:] = p.history.x.array

    def equilibrium_force(self, state: dict, phase_field: np.ndarray) -> float:
        """|Reaction force| (N/mm) of one equilibrium solve at the state's u with the pixel map
        ``phase_field`` as phi_gp (the state's displacement is the initial guess)."""
        p = self.problem
        self.u_map.scatter(state["displacement"], p.displacement)
        p.gauss_points_from_pixels(phase_field, p.phase_field_gp)
        p.solve_displacement(state["u"])
        return abs(p.reaction_force())

    def staggered(self, state: dict) -> tuple[np.ndarray, np.ndarray, int]:
        """(phi after one more pass, phi converged, passes) at the state's u with the FEM step:
        per pass solve u with phi_gp, H = max(H_k, psi0+(u)), nodal phase-field solve; until the
        max-norm change of phi_gp < stagger_tolerance or stagger_max_iterations passes."""
        p = self.problem
        self._set_state(state)
        previous = p.phase_field_gp.x.array.copy()
        one_more = None
        for iteration in range(1, self.stagger_max_iterations + 1):  # noqa: B007 (returned)
            p.solve_displacement(state["u"])
            p.update_history()
            self.fem_step.solve()
            current = p.pixels_from_gauss_points(p.phase_field_gp)
            if one_more is None:
                one_more = current
            change = float(np.max(np.abs(p.phase_field_gp.x.array - previous)))
            if change < self.spec["stagger_tolerance"]:
                break
            previous = p.phase_field_gp.x.array.copy()
        else:
            log.warning("%s increment %d: staggering not converged in %d passes (last change %.3g)",
                        self.spec["name"], state["increment"], self.stagger_max_iterations, change)
        return one_more, current, iteration

    def phase_fields(self, state: dict, switch_phase_field: np.ndarray) -> tuple[dict, dict]:
        """Every variant's pixel phi for one state (``switch_phase_field``: FEM's phi_gp pixel map at
        the switch-over, the floor of ``published``), and the staggering variants' pass counts."""
        history = state["history"]
        capped = self.capped(history)
        fields = {"fem": state["phase_field_gp"], "exact_uncapped": self.exact(history), "exact": self.exact(capped)}
        if self.network_raw is not None:
            fields["network_raw"] = self.network_raw(capped)
            fields["network_smoothed"] = self.network_smoothed(capped)
            fields["published"] = np.maximum(switch_phase_field, fields["network_smoothed"])
        one_more, converged, passes = self.staggered(state)
        fields.update(fem_one_more_pass=one_more, fem_converged=converged)
        return fields, {"fem_converged": passes, "fem_one_more_pass": 1}

    def replay(self, state: dict, switch_phase_field: np.ndarray, fem_peak: float,
               fem_force: float | None = None) -> tuple[list[dict], dict]:
        """Rows (one per variant) for one state, and the variants' phi maps. ``fem_peak``: N/mm;
        ``fem_force``: FEM's recorded force at the state's increment (N/mm, for the record)."""
        started = time.perf_counter()
        fields, passes = self.phase_fields(state, switch_phase_field)
        reference = state["phase_field_gp"]
        crack = reference >= self.crack_phi
        forces = {name: self.equilibrium_force(state, phi) for name, phi in fields.items()}
        rows = []
        for name in (v for v in VARIANTS if v in fields):
            phi = fields[name]
            difference = np.abs(phi - reference)
            rows.append({
                "increment": state["increment"], "u": state["u"], "variant": name,
                "phi_max_abs_error": float(difference.max()), "phi_mean_abs_error": float(difference.mean()),
                "phi_max": float(phi.max()), "crack_band_min": crack_band_min(phi, crack, self.band_radius_px),
                "reaction_force": forces[name], "force_vs_fem": (forces[name] - forces["fem"]) / fem_peak,
                "force_fraction": forces[name] / fem_peak,
                "fem_recorded_force_fraction": np.nan if fem_force is None else abs(fem_force) / fem_peak,
                "stagger_passes": passes.get(name, 0),
            })
        log.info("%s increment %d (u = %.4g mm): replayed in %.1f s; force / FEM peak: %s", self.spec["name"], state["increment"],
                 state["u"], time.perf_counter() - started, ", ".join(f"{r['variant']} {r['force_fraction']:.3f}" for r in rows))
        return rows, fields


# --------------------------------------------------------------------------- tables
def attribute(states: pd.DataFrame, fields: dict | None = None) -> list[dict]:
    """Per source (SOURCES): force difference (to - from) / FEM peak summarised over the states
    (RMS, signed mean, largest |.|) and the phi difference between the two variants (largest and
    mean |.| over pixels, largest / mean over the states). ``states``: one run's rows of
    :meth:`Replay.replay`; ``fields``: {increment: {variant: phi map}} (None: phi columns nan)."""
    rows = []
    for source, (start, end) in SOURCES.items():
        if not {start, end} <= set(states.variant):
            continue
        a = states[states.variant == start].set_index("increment")
        b = states[states.variant == end].set_index("increment")
        delta = b.force_fraction - a.force_fraction
        phi_max = phi_mean = np.nan
        if fields:
            diffs = [np.abs(fields[k][end] - fields[k][start]) for k in a.index]
            phi_max, phi_mean = float(max(d.max() for d in diffs)), float(np.mean([d.mean() for d in diffs]))
        rows.append({"source": source, "from_variant": start, "to_variant": end, "states": len(delta),
                     "force_rms": float(np.sqrt(np.mean(delta**2))), "force_mean": float(delta.mean()),
                     "force_max_abs": float(delta.abs().max()), "phi_max_abs": phi_max, "phi_mean_abs": phi_mean})
    return rows


def error_sources(cases: list[dict], stagger_max_iterations: int = 50, crack_phi: float = 0.95,
                  device="auto") -> tuple[pd.DataFrame, pd.DataFrame]:
    """The error split of each IFENN run in ``cases``.

    A case is a dict of paths: ``spec`` (the IFENN run's spec.json), ``mesh`` (the scene's XDMF),
    ``fem_dir`` (its FEM run: fields.h5, history.csv), ``ifenn_history`` (the published IFENN
    run's history.csv, for the whole-run context; absent or None: those columns are nan) and
    ``model`` (the trained PICNN; absent or None: no network variants); ``device``: where the network
    runs (:mod:`ifenn.device`).
    Returns (sources, states): one row per run and source (attribute() columns + the run's
    post-switch context, postswitch_error()), and one row per run, replayed state and variant
    (Replay.replay columns). Fractions of the FEM peak, see the module docstring.
    """
    from ifenn.device import network_device

    source_rows, state_rows = [], []
    for case in cases:
        spec = run_files.read_spec(case["spec"])
        fem_dir = Path(case["fem_dir"])
        fem_history = run_files.read_history(fem_dir)
        if case.get("ifenn_history"):
            figures = postswitch_error(pd.read_csv(case["ifenn_history"]), fem_history)
        else:
            figures = {**dict.fromkeys(("u_switch", "postswitch_increments", "postswitch_rms_error", "postswitch_max_error",
                                        "final_force_ifenn"), np.nan),
                       "fem_peak_force": float(fem_history.reaction_force.abs().max()),
                       "final_force_fem": float(abs(fem_history.reaction_force.iloc[-1]) / fem_history.reaction_force.abs().max())}
        context = {"run": spec["name"], "fem_run": spec["fem_run"], **figures}
        peak = context["fem_peak_force"]
        switch, _, states = saved_states(fem_dir / run_files.FIELDS)
        switch_phase_field = switch_state(fem_dir)[1]["phase_field_gp"]
        if not states:
            raise ValueError(f"FEM run {fem_dir} saved no state after its switch-over increment {switch}: nothing to replay")
        log.info("%s: %d FEM states after the switch-over increment %d", spec["name"], len(states), switch)
        replay = Replay(spec, case["mesh"], case.get("model"), stagger_max_iterations, crack_phi, network_device(spec, device))
        recorded = fem_history.set_index("increment").reaction_force
        run_rows, run_fields = [], {}
        for state in states:
            rows, fields = replay.replay(state, switch_phase_field, peak, recorded.get(state["increment"]))
            run_rows += rows
            run_fields[state["increment"]] = fields
        frame = pd.DataFrame(run_rows)
        state_rows += [{"run": spec["name"], **row} for row in run_rows]
        source_rows += [{"run": spec["name"], **row, **{k: v for k, v in context.items() if k != "run"}}
                        for row in attribute(frame, run_fields)]
    return pd.DataFrame(source_rows), pd.DataFrame(state_rows)
