"""The field's specimens against a measured or published curve (config ``specimens``).

Each run's force is that of the whole specimen: a scene that models a part of it behind mirror
planes (``symmetry_factor``) has its force multiplied back. Per run the table gives the peak
force, the displacement at the peak and the work of the load up to the end of the shorter of the
two curves, each beside the curve's own and as a ratio to it. The work is the area under the
force-displacement curve (trapezoids): once the specimen is cut it is the energy the fracture
dissipated, so it compares the two answers without depending on where the drop falls
(:func:`ifenn.studies.tables.metrics.work_of_load`).
"""

from __future__ import annotations

import pandas as pd

from ifenn.studies.tables.metrics import peak, work_of_load, work_rel_error

TABLE_COLUMNS = ["run", "peak_force", "u_peak", "work", "u_end", "peak_ratio", "u_peak_ratio", "work_ratio"]


def symmetry_factor(scene: dict) -> int:
    """How many copies of the scene make its specimen (1 unless it says ``symmetry_factor``)."""
    return int(scene.get("symmetry_factor", 1))


def specimen_table(curves: dict[str, pd.DataFrame], measured: pd.DataFrame) -> pd.DataFrame:
    """One row per run (``curves``: label -> frame with ``u`` and ``reaction_force``, the whole
    specimen's) and a first row for the measured or published curve (columns displacement_mm and
    the force). The work is taken up to the smaller of the two curves' last displacements."""
    force_column = [c for c in measured.columns if c != "displacement_mm"][0]
    mu, mf = measured["displacement_mm"].to_numpy(float), measured[force_column].to_numpy(float)
    m_peak, m_u = peak(mu, mf)
    rows = []
    for label, frame in {"measured": None, **curves}.items():
        u, f = (mu, mf) if frame is None else (frame["u"].to_numpy(float), frame["reaction_force"].to_numpy(float))
        u_end = min(u[-1], mu[-1])
        p, up = peak(u, f)
        rows.append({"run": label, "peak_force": p, "u_peak": up, "work": work_of_load(u, f, u_end), "u_end": u_end,
                     "peak_ratio": p / m_peak, "u_peak_ratio": up / m_u, "work_ratio": 1.0 + work_rel_error(u, f, mu, mf)})
    return pd.DataFrame(rows, columns=TABLE_COLUMNS)
