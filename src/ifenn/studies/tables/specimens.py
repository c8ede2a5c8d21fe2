"""The field's specimens against a measured or published curve (config ``specimens``).

Each run's force is that of the whole specimen: a scene that models a part of it behind mirror
planes (``symmetry_factor``) has its force multiplied back. Per run the table gives the peak
force, the displacement at the peak and the work of the load up to the end of the shorter of the
two curves, each beside the curve's own and as a ratio to it; with a measured scatter band, whether
the peak lies between the band's edges' peaks and the share of the curve (over the band's range of
u) that lies between its edges. The work is the area under the
force-displacement curve (trapezoids): once the specimen is cut it is the energy the fracture
dissipated, so it compares the two answers without depending on where the drop falls
(:func:`ifenn.studies.tables.metrics.work_of_load`).
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from ifenn.studies.tables.metrics import peak, work_of_load, work_rel_error

TABLE_COLUMNS = ["run", "peak_force", "u_peak", "work", "u_end", "peak_ratio", "u_peak_ratio", "work_ratio"]


def symmetry_factor(scene: dict) -> int:
    """How many copies of the scene make its specimen (1 unless it says ``symmetry_factor``)."""
    return int(scene.get("symmetry_factor", 1))


def in_band(u, force, band: pd.DataFrame) -> dict:
    """Where a curve lies against a scatter band (``band``: displacement_mm, the lower edge's force, the
    upper edge's): ``peak_in_band`` (its peak between the edges' peaks) and ``in_band_fraction`` (the
    share of its points with u inside the band's range whose force lies between the edges there)."""
    bu, lower, upper = (band.iloc[:, k].to_numpy(float) for k in range(3))
    u, force = np.asarray(u, float), np.asarray(force, float)
    inside = (u >= bu[0]) & (u <= bu[-1])
    lo, hi = np.interp(u[inside], bu, lower), np.interp(u[inside], bu, upper)
    within = (force[inside] >= lo) & (force[inside] <= hi)
    return {"peak_in_band": bool(lower.max() <= force.max() <= upper.max()),
            "in_band_fraction": float(within.mean()) if within.size else float("nan")}


def specimen_table(curves: dict[str, pd.DataFrame], measured: pd.DataFrame, band: pd.DataFrame | None = None) -> pd.DataFrame:
    """One row per run (``curves``: label -> frame with ``u`` and ``reaction_force``, the whole
    specimen's) and a first row for the measured or published curve (columns displacement_mm and
    the force). The work is taken up to the smaller of the two curves' last displacements. With a
    scatter ``band`` (:func:`in_band`), its columns too."""
    force_column = [c for c in measured.columns if c != "displacement_mm"][0]
    mu, mf = measured["displacement_mm"].to_numpy(float), measured[force_column].to_numpy(float)
    m_peak, m_u = peak(mu, mf)
    rows = []
    for label, frame in {"measured": None, **curves}.items():
        u, f = (mu, mf) if frame is None else (frame["u"].to_numpy(float), frame["reaction_force"].to_numpy(float))
        u_end = min(u[-1], mu[-1])
        p, up = peak(u, f)
        rows.append({"run": label, "peak_force": p, "u_peak": up, "work": work_of_load(u, f, u_end), "u_end": u_end,
                     "peak_ratio": p / m_peak, "u_peak_ratio": up / m_u, "work_ratio": 1.0 + work_rel_error(u, f, mu, mf),
                     **(in_band(u, f, band) if band is not None else {})})
    return pd.DataFrame(rows, columns=TABLE_COLUMNS + (["peak_in_band", "in_band_fraction"] if band is not None else []))
