"""Physical parameters of a batch of worm worlds: the contract between configs, randomization and the solver.

Every per-world field is either one float (shared by all worlds) or an array of shape ``(num_worlds,)``;
:func:`per_world` broadcasts either to ``(num_worlds,)``. Vector fields take ``(3,)`` or ``(num_worlds, 3)``.
Defaults follow the paper (Swaminathan et al., RA-L 2021) and the calibrations. SI units.

Frames: world z is up, the floor is z = 0 (tilted by ``floor_incline`` about world y), the worm lies along +x with
its tail at the smaller x. Magnet slots in every world: 0 = EPM, 1 = tail IPM, 2 = centre IPM, 3 = head IPM.
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields, replace

import numpy as np

from warpworm.ids import MAGNET_MODELS

N52_MOMENT_PER_VOLUME = 0.9e6
"""Fitted magnetization of the paper's N52 magnets: 0.9 A·m² per cm³ = 0.9e6 A/m (the paper's fit)."""

MAGNET_SLOTS = ("epm", "ipm_tail", "ipm_centre", "ipm_head")
EPM, IPM_TAIL, IPM_CENTRE, IPM_HEAD = range(4)

GAITS = ("peristaltic", "omega", "inchworm")


@dataclass
class WormParams:
    """Per-world parameters of the worm, its magnets, the floor and the EPM path."""

    # --- geometry (shared topology: n_units is one int for the whole batch) ---
    n_units: int = 6
    """Number of prism units along the worm, shared by all worlds (topology), int."""
    a: float | np.ndarray = 0.020
    """Side of the triangular cross-section [m], shape () or (W,)."""
    b: float | np.ndarray = 0.008
    """Length of each of the two panels of a unit along the worm, unfolded [m], shape () or (W,)."""
    l0: float | np.ndarray = 0.080
    """Rest length of the whole worm [m]; sets the rest fold angle by eq. (7), shape () or (W,)."""

    # --- sheet and creases ---
    sheet_density: float | np.ndarray = 0.15
    """Areal density of the sheet [kg/m²] (mineral paper ≈ 0.15), shape () or (W,)."""
    hinge_stiffness: float | np.ndarray = 0.005
    """Crease stiffness k_α per metre of crease [N·m/rad/m = N/rad], shape () or (W,): the default material,
    mineral paper (warpworm.physics.materials; the paper's 11.55 is Kangaroo's unitless strength and does not convert)."""
    bar_stiffness: float | np.ndarray = 20.0
    """Axial rigidity EA of every bar but the valley rings [N] (force per unit Cauchy strain), shape () or (W,).
    Near-rigid: strains of ~1e-3 under the magnets' ~0.02 N. Not stiffer by default: the implicit solver reads the
    floor's normal forces off the bar forces, and a float32 position (~4e-9 m rounding at 0.05 m) gives a bar of
    EA / L0 ~ 1e6 N/m (EA = 1e4) a force noise of ~4 mN, more than a vertex's share of the worm's weight (~1 mN);
    at 20 N it is ~8 µN."""
    valley_bar_stiffness: float | np.ndarray = 0.3
    """Axial rigidity EA_w of the VALLEY-ring (waist) bars at the unit middles [N], shape () or (W,): the sheet's
    in-plane compliance. The tube is isostatic: these bars stand for the panel bending near the
    waists that lets the paper bellows fold, so they must be far softer than ``bar_stiffness`` for the worm to
    shorten under the magnets (default: mineral paper, warpworm.physics.materials)."""
    waist_close_strain: float | np.ndarray = 0.3
    """How far a waist (VALLEY) bar may shorten, as a strain magnitude ε_c [1], before it turns as stiff as the rigid
    bars, shape () or (W,). The bellows' folding mode shrinks its waists (they close completely at about 17 %
    shortening), so this caps how far each unit can contract."""
    waist_stop_strain: float | np.ndarray = 0.3
    """Stretch ε_t [1] beyond which a waist (VALLEY) bar turns as stiff as the rigid ones (``bar_stiffness``), shared
    shape () or (W,): the panels it stands for bend only so far. Without the stop a hard squeeze flattens the waist
    triangles into slivers (their crease gradients blow up) or pinches the waist through the axis (the waist closes
    at α = 92.4°)."""
    fold_limit_stiffness: float | np.ndarray = 2.0
    """NoFoldThrough barrier k_lim per metre of crease [N·m/rad/m = N/rad], shape () or (W,): a crease past its range
    (mountain [−π, 0], valley [0, π]) feels k_lim L (φ − bound). A material constant of its own, not a multiple of
    k_α, so softening the crease does not soften the barrier (MERLIN stiffens the hinge outside its range likewise)."""
    damping: float | np.ndarray = 2.0
    """Linear velocity damping rate [1/s], shape () or (W,)."""
    hinge_damping: float | np.ndarray = 1.0e-4
    """Crease damping c_α per metre of crease [N·m·s/rad/m]: a hinge resists folding speed with c_α L dψ/dt,
    shape () or (W,). Default: mineral paper's (warpworm.physics.materials), a crease relaxation time c_α / k_α = 20 ms.
    Without it a soft worm close to the EPM snaps and crumples."""

    # --- floor ---
    mu_static: float | np.ndarray = 0.268
    """Static friction coefficient (paper's slope test), shape () or (W,)."""
    mu_kinetic: float | np.ndarray = 0.24
    """Kinetic friction coefficient, <= mu_static, shape () or (W,)."""
    friction_backward_ratio: float | np.ndarray = 1.0
    """Both friction coefficients tail-ward over head-ward (along −x / +x of the worm's rest axis, in the floor's
    plane), shape () or (W,): 1 (default) is the paper's isotropic friction; > 1 a skin that grips against sliding
    backward (setae, scales, a sheet's cut edges), < 1 against sliding forward. In between the factor follows the
    direction smoothly ((1 + ratio) / 2 sideways), and the friction is the gradient of a convex dissipation
    (``kernels.substep.skin_profile``, ``friction_force``)."""
    floor_incline: float | np.ndarray = 0.0
    """Floor slope about world +y [rad]; positive raises the floor toward +x (the worm climbs going forward)."""
    support_thickness: float | np.ndarray = 0.003
    """Thickness of the support plate the worm walks on [m] (its top face is the floor, z = 0; the EPM moves
    beneath it, so the closest approach h is at least this), shape () or (W,)."""
    gravity: float | np.ndarray = 9.81
    """Gravitational acceleration magnitude [m/s²], along −z, shape () or (W,)."""

    # --- magnets ---
    magnet_model: str = "dipoles"
    """'dipoles' (paper's aggregation) or 'analytic' (exact fields), shared by the batch."""
    dipole_density: float | np.ndarray = 64e6
    """Dipoles per m³ for the 'dipoles' model (64 per cm³), shape () or (W,)."""
    magnet_mass_density: float | np.ndarray = 7500.0
    """Mass density of the magnets [kg/m³] (NdFeB ≈ 7.5 g/cm³), shape () or (W,)."""
    epm_size: np.ndarray = field(default_factory=lambda: np.array([0.010, 0.010, 0.040]))
    """EPM cuboid extents (x, y, z) in its own frame [m]; magnetized along its own +z, shape (3,) or (W, 3)."""
    epm_moment: float | np.ndarray = 0.9e6 * 4e-6
    """EPM dipole moment magnitude [A·m²] (0.9 A·m²/cm³ × 4 cm³), shape () or (W,)."""
    ipm_diameter: float | np.ndarray = 0.010
    """IPM disk diameter [m], shape () or (W,)."""
    ipm_thickness: float | np.ndarray = 0.001
    """IPM disk thickness [m], shape () or (W,)."""
    ipm_moment: np.ndarray = field(
        default_factory=lambda: np.full(3, 0.9e6 * np.pi * 0.005**2 * 0.001)
    )
    """Moment magnitudes of the (tail, centre, head) IPMs [A·m²], axial, shape (3,) or (W, 3)."""

    # --- EPM path (paper §IV-C) ---
    gait: str | np.ndarray = "peristaltic"
    """One of GAITS; fixes the EPM orientation and placement; shape () or (W,) (str)."""
    backward: bool | np.ndarray = False
    """Drive the worm toward −x instead of +x; shape () or (W,) (bool)."""
    wavelength: float | np.ndarray = 0.02
    """EPM path wavelength w [m]: distance the EPM advances per cycle, shape () or (W,)."""
    amplitude: float | np.ndarray = 0.03
    """EPM path amplitude a [m]: vertical swing of the EPM away from (below) its closest approach, shape () or (W,)."""
    closest_approach: float | np.ndarray = 0.015
    """EPM closest approach h [m]: the smallest gap between the origami base (the floor, z = 0) and the nearest face
    of the EPM, which moves beneath the support plate (>= ``support_thickness``), shape () or (W,)."""
    orientation: float | np.ndarray = float("nan")
    """EPM moment angle θ in the x–z plane from +x toward +z (up) [rad]: −π/2 south pole up, 0 north pole forward,
    +π/2 north pole up; NaN takes the gait preset's value (warpworm.physics.gaits.GAIT_ORIENTATION)."""
    cycle_period: float | np.ndarray = 1.0
    """Duration of one EPM cycle [s], shape () or (W,)."""
    closest_approach_scale: float | np.ndarray = 1.0
    """Factor on ``closest_approach`` [1], shape () or (W,): lets a dataset config randomize h *around* each
    sample's gait preset (e.g. {uniform: [0.9, 1.2]}), whatever gait it draws. The gap used is h × this."""
    wavelength_scale: float | np.ndarray = 1.0
    """Factor on ``wavelength`` [1], shape () or (W,), as ``closest_approach_scale``."""

    def names(self) -> list[str]:
        return [f.name for f in fields(self)]


def per_world(value, num_worlds: int, inner_shape: tuple[int, ...] = ()) -> np.ndarray:
    """Broadcast a shared value or a per-world array to ``(num_worlds, *inner_shape)`` float64.

    Raises ``ValueError`` naming the shapes when the value fits neither form.
    """
    arr = np.asarray(value, dtype=np.float64)
    if arr.shape == inner_shape:
        return np.broadcast_to(arr, (num_worlds,) + inner_shape).copy()
    if arr.shape == (num_worlds,) + inner_shape:
        return arr.copy()
    raise ValueError(
        f"expected shape {inner_shape} (shared) or {(num_worlds,) + inner_shape} (per world), got {arr.shape}"
    )


def parse_overrides(items) -> dict[str, float]:
    """``["FIELD=VALUE", ...]`` (the commands' ``--set``) -> {field: float}; a ValueError names the item, the field
    and what was expected."""
    fields_ = set(WormParams().names())
    out = {}
    for item in items:
        key, sep, value = str(item).partition("=")
        if not sep or key not in fields_:
            raise ValueError(f"--set {item!r}: expected FIELD=VALUE with FIELD one of WormParams' fields")
        try:
            out[key] = float(value)
        except ValueError:
            raise ValueError(f"--set {item!r}: got {value!r}; expected a number") from None
    return out


VECTOR_FIELDS = ("epm_size", "ipm_moment")
"""WormParams fields whose per-world form is (W, 3) (shared: (3,))."""


def slice_worlds(params: WormParams, num_worlds: int, lo: int, hi: int) -> WormParams:
    """``params`` for worlds [lo, hi) of ``num_worlds``: every per-world array field sliced (``gait`` and
    ``backward`` too when they are per world), shared values kept. Worlds never interact, so a batch split this way
    and run share by share gives each world the result it has in the whole batch."""
    changes = {}
    for f in fields(params):
        v = getattr(params, f.name)
        if isinstance(v, (str, bool)) or v is None:
            continue
        a = np.asarray(v)
        per_world = a.ndim == 2 if f.name in VECTOR_FIELDS else a.ndim == 1
        if per_world and a.shape[0] == num_worlds:
            changes[f.name] = a[lo:hi].copy()
    return replace(params, **changes)
