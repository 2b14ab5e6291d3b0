"""Sheet materials: one physical parameterization of the origami's stiffness, and three named presets.

The worm is a bar-and-hinge model. Its stiffness and damping are material constants:

- ``hinge_stiffness`` k_α [N·m/rad per metre of crease = N/rad]: the crease's rotational spring. A crease of length
  L resists a fold-angle change Δφ with the moment k_α L Δφ.
- ``valley_bar_stiffness`` EA_w [N]: the axial rigidity of the waist-ring (VALLEY) bars. The tube is isostatic as a
  bar framework (rank 3V − 6): it can only shorten if some bars give, and the waist bars stand for the panel
  bending near the waists that lets a real paper bellows fold. This is the in-plane compliance of the sheet.
- ``bar_stiffness`` EA [N]: every other bar, near-rigid (panels do not stretch).
- ``hinge_damping`` c_α [N·m·s/rad per metre of crease]: the crease's viscous resistance to folding speed (paper
  creases are viscoelastic). Without it a soft worm near the EPM snaps dynamically and crumples; 20 ms relaxation
  (c_α = 1e-4 for mineral paper) keeps the force-plate runs and closer approaches stable.

The fold-through barrier (``fold_limit_stiffness``) is independent of all three.

Kangaroo's Hinge goal (K2Goals ``Hinge.cs``, the paper's crease) moves each wing vertex by k·L²·Δθ / (4 (H₀ + H₁))
with H the wing heights: for equal wings that is a rotational stiffness k·L²/8 per crease, growing with L², whereas a
sheet's crease moment grows with L. The paper's k_α = 11.55 has no stated length unit and its magnet goal's weight is
not given, so it cannot be converted to N/rad; like the paper (§IV-B) we calibrate k_α against compression and
3-point flexure curves instead (``warpworm experiment compression|flexure --fit TABLE.csv``).

Presets (:data:`MATERIALS`): the paper's Fig. 7 gives no number in its text, only that the three materials rank
mineral paper < tracing paper < BoPET in stiffness and that the compression and flexure fits agree. The values are
our targets: mineral paper is the default worm's material (the gait presets are tuned for it); tracing paper and
BoPET are 2× and 5× stiffer in both crease and waist, with their areal densities (mineral paper ≈ 0.15 kg/m²
for a 0.15 mm stone paper, tracing paper ≈ 0.09 kg/m², 0.125 mm BoPET ≈ 0.17 kg/m²).
"""

from __future__ import annotations

from dataclasses import replace

from warpworm.physics.params import WormParams

MATERIALS: dict[str, dict[str, float]] = {
    "mineral_paper": dict(hinge_stiffness=0.005, valley_bar_stiffness=0.3, sheet_density=0.15, hinge_damping=1.0e-4),
    "tracing_paper": dict(hinge_stiffness=0.010, valley_bar_stiffness=0.6, sheet_density=0.09, hinge_damping=2.0e-4),
    "bopet": dict(hinge_stiffness=0.025, valley_bar_stiffness=1.5, sheet_density=0.17, hinge_damping=5.0e-4),
}
"""Named sheet materials: k_α [N/rad], EA_w [N], areal density [kg/m²], crease damping c_α [N·m·s/rad/m] (a crease
relaxation time c_α / k_α of 20 ms for all three)."""

DEFAULT_MATERIAL = "mineral_paper"


def material_params(name: str, base: WormParams | None = None) -> WormParams:
    """``base`` (default ``WormParams()``) with the named material's stiffness and density."""
    if name not in MATERIALS:
        raise ValueError(f"material: {name!r} is not a known material; expected one of {sorted(MATERIALS)}")
    return replace(base or WormParams(), **MATERIALS[name])
