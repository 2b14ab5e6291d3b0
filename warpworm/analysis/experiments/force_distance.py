"""§IV-A, Fig. 5: the attraction of two 1 cm³ N52 cubes vs gap, the dipole model at several densities and the exact
model beside the closed-form table."""

from __future__ import annotations

import numpy as np

from warpworm.analysis.calibration import pair_forces
from warpworm.physics import magnets as mg

CUBE_TABLE = {
    1: 26.04212, 2: 18.76765, 3: 14.05910, 5: 8.401509, 7: 5.308457, 10: 2.879273, 15: 1.214808, 20: 0.592872,
    30: 0.189106,
}
"""Closed-form attraction [N] of two coaxial 10 mm cubes, 0.9 A·m² each, unlike poles facing, by face gap [mm]
(shared/DESIGN-NOTES.md; closed form and magpylib agree to 3e-7)."""


def force_distance(gaps=None, densities=(1e6, 8e6, 64e6), moment: float = 0.9, side: float = 0.010) -> dict:
    """Attraction [N] between two coaxial cubes (side ``side``, ``moment`` each, unlike poles facing) vs face gap.

    Returns ``gap (K,)`` [m], ``analytic (K,)`` [N], ``dipoles (D, K)`` [N] (one row per density [1/m³]),
    ``densities (D,)``, ``table_gap (T,)`` [m] and ``table_force (T,)`` [N] (DESIGN-NOTES closed form),
    ``analytic_at_table (T,)`` and ``dipoles_at_table (D, T)``, and a summary of relative errors vs the table.
    """
    gaps = np.geomspace(0.5e-3, 40e-3, 60) if gaps is None else np.asarray(gaps, np.float64)
    cube = mg.Cuboid((side, side, side), moment=(0.0, 0.0, moment))
    tg = np.array(sorted(CUBE_TABLE), np.float64) * 1e-3
    tf = np.array([CUBE_TABLE[k] for k in sorted(CUBE_TABLE)])
    allg = np.concatenate([gaps, tg])
    ana = pair_forces(cube, cube, allg, model="analytic")
    dip = np.stack([pair_forces(cube, cube, allg, model="dipoles", density=d) for d in densities])
    K = len(gaps)
    rel_a = ana[K:] / tf - 1.0
    rel_d = dip[:, K:] / tf - 1.0
    summary = {"analytic_max_rel_err_vs_table": float(np.abs(rel_a).max())}
    for d, r in zip(densities, rel_d):
        summary[f"dipoles_{d / 1e6:g}_per_cm3_rel_err_at_1mm"] = float(r[0])
        summary[f"dipoles_{d / 1e6:g}_per_cm3_max_rel_err_from_5mm"] = float(np.abs(r[tg >= 5e-3 - 1e-12]).max())
    return {
        "gap": gaps, "analytic": ana[:K], "dipoles": dip[:, :K], "densities": np.asarray(densities, np.float64),
        "table_gap": tg, "table_force": tf, "analytic_at_table": ana[K:], "dipoles_at_table": dip[:, K:],
        "summary": summary,
    }
