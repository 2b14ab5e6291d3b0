"""The paper's virtual experiments (Swaminathan et al., RA-L 2021, §IV), batched: one Simulator per experiment.

Every function returns a dict with NumPy arrays and a ``"summary"`` dict of plain floats / strings (JSON-ready with
:func:`to_jsonable`). A sweep (hinge stiffnesses, slopes, gaits) is W worlds of one :class:`~warpworm.sim.simulator.
Simulator`; nothing loops over worlds on the host. SI units throughout (the plots convert to mm / mN).

==================  ====================================================================================================
force_distance      §IV-A, Fig. 5: attraction of two 1 cm³ N52 cubes (0.9 A·m², unlike poles facing) vs gap, dipole
                    model at several densities and the exact (analytic) model, beside the closed-form table.
compression         §IV-B, Fig. 6/7: tail section anchored, head section pushed along −x in quasi-static increments;
                    force vs displacement, one world per hinge stiffness k_α; linear quasi-static prediction beside it.
flexure             §IV-B: worm lifted on two supports near its ends, centre section pushed down; force vs deflection
                    per k_α (force relative to the unloaded preload), linear prediction beside it.
slope               §IV-F: worm (no magnets) on inclines β across atan(μs); slide along the slope vs time and the
                    Coulomb prediction ½ g (sin β − μk cos β) t².
force_plate         §IV-D, Fig. 9/10: tail tied by anchors to a fixed point while each gait runs; anchor force vs time.
strain              §IV-G, Fig. 12: Cauchy strain of every bar over a gait: max / mean |strain| per bar.
deformation         §IV-E, Fig. 11: the four deformation ratios (adjacent segment-centre distances over rest) vs time
                    and the net displacement, per gait.
==================  ====================================================================================================

Gait experiments run the three gait presets (:func:`warpworm.physics.gaits.preset_params`) as three worlds of one batch: the
presets' per-gait scalars become per-world arrays and each world gets its own gait's EPM path.

Modules: ``common`` (split_run, section_vertices, NO_MAGNETS, to_jsonable, save_json), ``force_distance``,
``quasi_static`` (compression, flexure, the linear prediction), ``slope``, ``gait_experiments`` (run_gaits,
force_plate, strain, deformation, rise_fall_times). Every public name is importable from here.
"""

from __future__ import annotations

from warpworm.analysis.experiments.common import (EXPERIMENTS, NO_MAGNETS, dt_substeps, lift_worm, save_json,
                                                  section_vertices, split_run, to_jsonable)
from warpworm.analysis.experiments.force_distance import CUBE_TABLE, force_distance
from warpworm.analysis.experiments.gait_experiments import (GAIT_RECORD, deformation, force_plate, gait_model,
                                                            rise_fall_times, run_gaits, strain)
from warpworm.analysis.experiments.quasi_static import (DEFAULT_HINGE_SWEEP, compression, flexure,
                                                        linear_anchor_response, linear_anchor_responses)
from warpworm.analysis.experiments.slope import slope
from warpworm.analysis.world_split import world_shares  # the split's shares (experiment --workers)
