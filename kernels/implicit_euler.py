"""The default solver: implicit Euler with Newton steps on a banded direct solve, one thread per world.

Kernels only; the host orchestration is :class:`warpworm.sim.simulator.Simulator`.
:func:`implicit_step` is launched 1-D over worlds (``world = wp.tid()``); each thread runs its world's substeps. A
substep of length dt finds the positions x that minimise

    ½ |x − x̃|²_M / dt² + E(x),      x̃ = x_n + dt v',   v' = v_n / (1 + c dt) + dt (g + M⁻¹ f_ext)

(implicit Euler: gravity, the step's magnetic force and the linear velocity damping c are in x̃), with E the elastic
energy of the worm:

- every bar a spring ½ (EA / L0)(L − L0)² (stiff bars near-rigid, the valley rings soft; Cauchy strain reported),
  and a soft waist bar strained past its stop |ε| = ε_s a one-sided spring ½ (EA_s / L0)(L − L0(1 ± ε_s))²;
- every crease ½ k_α L (φ − φ0)² plus its damping as the implicit dissipation ½ (c_α L / dt)(φ − φ_n)², and the
  NoFoldThrough limits as a one-sided spring k_lim L beyond the bound (0 for mountain/valley creases), with k_lim
  (``fold_limit_stiffness``) its own material constant: a barrier that scaled with k_α would soften with the crease
  and let a soft worm fold through;
- every hinge wing a panel contact barrier ½ κ q² once its altitude over the hinge falls below 0.02 of the hinge's
  length (:func:`~.common.wing_contact`): a panel does not fold flat onto itself;
- every anchor ½ k |x − target|² (so the force plate reads k (x − target), the force it applies).

Gauss–Newton steps (bar and crease Hessians kept positive semi-definite: the compressive geometric stiffness and
the crease curvature terms dropped) solve it, at most ``newton`` of them, until a step (the second or later) moves no
vertex farther than ``newton_tol``; each assembles the gradient and the 3V × 3V Hessian as 3×3 vertex blocks in a
banded per-world scratch and factors it (:mod:`warpworm.kernels.band_cholesky`). With ``refactor`` = 0 (chord
steps, the band default) only the first step of every other substep, and a step after a contact changed, assembles
and factors the Hessian; the others solve with the last factor against a fresh gradient (the first step of the
substep after a factored one in the same launch too, if no contact changed status in between; one whose substep
then had to refactor leaves the next substep a fresh factor), and one that would not halve the
last step is not taken (the next assembles and factors at the same x): a stale factor (near-rigid bars turned,
kinetic friction's stiffness changed) never moves a world, where taking such a step first and refactoring after
could throw one past its strain limit (an axial squeeze at 2 ms did). Chord steps contract more slowly than fresh
ones, so their substep ends only when the error estimate θ/(1 − θ)·step (θ the last contraction) is also below
``STOP_ERROR`` times the tolerance (measured against 12 fresh steps per substep: as close as fresh factors every
substep came).

Floor: a vertex on the floor (touching at the end of the last substep, or carried below it) moves only along it
(its rows of the Newton step are projected, P H P). Before every Newton step after the first, the floor's force at
each contact is read from the gradient, F = ∂Φ/∂x (what holds the vertex against the rest of the implicit step): a
contact the floor would have to pull lets go, a free vertex the last step put below the floor lands. Friction
(eq. 8 of the paper) is a force in the Newton problem with that normal force F_n: static as a stiff viscous force
−(mu_s F_n / ε) v_t reaching mu_s F_n at ε = ``slip_speed`` (a held worm creeps at most ~ε), kinetic as
−mu_k F_n v_t / |v_t|; a stuck vertex breaks loose when the viscous force it needed exceeds mu_s F_n, a sliding one
sticks when the kinetic force reverses its motion or when it starts a substep slower than ε. A last pass catches
vertices that reached the floor in the last step; then v = v' + (x − x̃) / dt.

Why: the bars are near-rigid on 1e-5 kg vertices. An XPBD sweep per substep caps their stiffness near m/dt² (the
Gauss–Seidel and Jacobi XPBD solvers of this package's first version: "rigid" bars strained by percents), a Gauss–Seidel crease sweep
composed with a direct bar projection was linearly unstable, and explicit crease forces projected on rigid bars are
only stable below ~100–200 µs and lose stability as the bellows approaches its snap-through (all measured:
docs/dynamics.md). Implicit Euler with a direct solve is unconditionally stable, has the exact statics of E (no mass
in the equilibrium, unlike a one-pass XPBD compliance) and converges at first order as dt is halved.
"""

from __future__ import annotations

import warp as wp

from warpworm import ids

from .band_cholesky import (ALL_ROWS, band_add_block, band_add_gauss_newton3, band_add_gauss_newton4,
                            band_cholesky_factor, band_cholesky_solve)
from .common import (crease_at_substep_end, dihedral_angle_gradient_and_normals, fold_range, freeze_world, pw,
                     wing_contact_of_normal, wrap_angle)

wp.set_module_options({"enable_backward": False})

CONTACT_FREE = wp.constant(0)
CONTACT_SLIDING = wp.constant(1)  # on the floor, kinetic friction
CONTACT_STUCK = wp.constant(2)  # on the floor, static friction (regularised: a stiff viscous force)
CONTACT_FIXED = wp.constant(3)  # a vertex of infinite mass (never moves; reported as free)
CONTACTS_CHANGED = wp.constant(1)  # update_contacts: a vertex changed its contact status
CONTACTS_LANDED = wp.constant(2)  # update_contacts: a free vertex landed (its position moved)
WORLD_CRUMPLED = wp.constant(ids.WORLD_CRUMPLED)  # ``unstable`` flag of a crumpled world (ids: the statuses)
CHORD_CONTRACTION = wp.constant(0.5)  # a chord step is taken only if it is shorter than this times the last step
STOP_ERROR = wp.constant(0.1)  # a chord step ends a substep only if θ/(1 − θ)·step is below this times the tolerance


@wp.func
def mass_over_dt2(w_inv: float, inv_dt2: float) -> float:
    """m / dt² [N/m] of a vertex of inverse mass ``w_inv`` (1 for a vertex of infinite mass, which never moves: it
    only keeps the Newton matrix definite)."""
    if w_inv > 0.0:
        return inv_dt2 / w_inv
    return 1.0


@wp.func
def floor_landing(p0: wp.vec3, vel: wp.vec3, n: wp.vec3, mu_s: float, mu_k: float, dt: float):
    """Position-level floor contact and friction (eq. 8 of the paper) of a free vertex that reached the floor only in
    the last Newton step of a substep.

    ``p0`` its position at the start of the substep, ``vel`` = (x − p0) / dt its velocity over the substep (kept
    apart from p0 so that a penetration of ~g dt² ≈ 2e-8 m at 50 µs is not lost in the float32 rounding of a ~0.1 m
    position), ``n`` the floor normal (floor through the origin). A penetration d is removed along n; the tangential
    motion is cancelled if it is at most mu_s d (stuck), otherwise reduced by mu_k d / dt (sliding: f = mu_k F_n
    over the substep with F_n = m d / dt²). Returns (p, vel, status, d), status CONTACT_FREE when it did not touch.
    """
    depth = wp.max(-(wp.dot(p0, n) + dt * wp.dot(vel, n)), 0.0)
    out = CONTACT_FREE
    if depth > 0.0:
        vel = vel + n * (depth / dt)
        vn = wp.dot(vel, n)
        vt = vel - n * vn
        vt_len = wp.length(vt)
        if vt_len * dt <= mu_s * depth:
            vel = n * vn  # stick: tangentially back to exactly where the substep started
            out = CONTACT_STUCK
        else:
            vel = vel - vt * (mu_k * depth / (dt * vt_len))
            out = CONTACT_SLIDING
    return p0 + vel * dt, vel, out, depth


@wp.func
def newton_start(status: int, vel: wp.vec3, v_old: wp.vec3, h0: float, n: wp.vec3, inv_dt: float) -> wp.vec3:
    """The velocity the Newton iteration of a substep starts from (x = x_n + dt · this), for a vertex of contact
    ``status`` with inertial velocity ``vel`` (x̃'s), last velocity ``v_old`` and height ``h0`` above the floor.

    A warm start: a moving vertex starts from the velocity it carries over, not from x̃, whose dt² (g + M⁻¹ f_ext)
    is ~40 µm at 2 ms for a worm that gravity and the floor hold at rest, 200× the tolerance; the carried-over
    velocity is what a near-quasi-static worm keeps. Measured over 5 cycles of each gait preset: 2.6–3.2 Newton steps
    per 1 ms substep instead of 3.7–4.0, 3.1–4.1 per 2 ms instead of 4.7–5.9, the same gaits to 0.01 mm
    (docs/dynamics.md, "Newton convergence"; since the contacts start where this velocity takes the vertices,
    :func:`starting_contact`, 2.5–3.6 full steps per 2 ms). Only the start moves: x̃ and the equations do not (the
    contacts' statuses follow the iterates, so a different start may end on another contact set within the
    tolerance). A
    free vertex starts no lower than the floor; a stuck one where it is along the floor (and a vertex on the floor no
    higher than it is: only an inertial velocity into the floor moves it, to the floor at most); one that is fixed
    (infinite mass) keeps ``vel`` (zero)."""
    if status == CONTACT_FIXED:
        return vel
    if status == CONTACT_FREE:
        gn = wp.dot(v_old, n)
        return v_old + n * (wp.max(gn, -h0 * inv_dt) - gn)
    start = n * wp.max(wp.min(wp.dot(vel, n), 0.0), -h0 * inv_dt)
    if status == CONTACT_SLIDING:
        start = start + (v_old - n * wp.dot(v_old, n))
    return start


@wp.func
def starting_contact(w_inv: float, was: int, vel: wp.vec3, v_old: wp.vec3, h0: float, n: wp.vec3, dt: float,
                     slip_speed: float) -> int:
    """A vertex's contact status at the start of a substep: FIXED for infinite mass; on the floor and not pulled
    off it (touching at the end of the last substep, status ``was``, with its inertial velocity ``vel`` into the
    floor or the velocity it carries, ``v_old``, not lifting it off: v_old · n ≤ ``slip_speed``), or landing on it
    (free, and ``v_old`` takes it below the floor within ``dt``): stuck or sliding by the speed along the floor it
    carries (a contact moving along the floor is sliding whatever it did in the last substep, e.g. a worm kicked at
    rest); else FREE. (Shared by both kernels.)

    Why ``v_old`` and not ``vel`` for a free vertex: the Newton iteration starts from ``v_old``
    (:func:`newton_start`), and ``vel`` lacks the elastic forces. A vertex hovering 25 µm above the floor, held up
    by the sheet while gravity and the EPM pull it down, has ``vel`` ~0.06 m/s into the floor: predicted a contact,
    it was let go at the first contact update (the floor would have had to pull with ~6 mN), and releasing it
    shifted the load so that two neighbours let go and landed again: 4.4 Newton steps per substep in the
    peristaltic gait instead of 2.5 (docs/dynamics.md, "Newton convergence"). A free vertex that does reach the
    floor in the first Newton step lands at the first contact update.

    Why ``v_old`` also keeps a vertex on the floor: in omega the EPM pulls the end mounts' vertices up harder than
    gravity (``vel`` points off the floor) while the sheet holds them down; started free, such a vertex landed again
    in the first Newton step of every substep, a fresh factorization each time (97 landings in 500 substeps). Kept
    on the floor, it lets go at the first contact update if the floor would have to pull. Omega: 9.4 → 7.6 Newton
    steps and 3.0 → 1.6 factorizations per 4 ms step; the three gaits the same to 0.004 mm over 5 cycles."""
    if not (w_inv > 0.0):
        return CONTACT_FIXED
    # on the floor, it stays if its inertial velocity presses it in or the velocity it carries does not lift it off
    stays = wp.dot(vel, n) < 0.0 or wp.dot(v_old, n) <= slip_speed
    if (was != CONTACT_FREE and stays) or (was == CONTACT_FREE and h0 + dt * wp.dot(v_old, n) < 0.0):
        vt_old = v_old - n * wp.dot(v_old, n)
        return wp.where(wp.length(vt_old) > slip_speed, CONTACT_SLIDING, CONTACT_STUCK)
    return CONTACT_FREE


@wp.func
def landing_floor_force(h0: float, vel: wp.vec3, n: wp.vec3, dt: float, w_inv: float, inv_dt2: float) -> wp.vec3:
    """The floor's first estimate of its normal force on a vertex that lands this substep: m/dt² times the depth
    its inertial velocity ``vel`` would take it below the floor from height ``h0`` (shared by both kernels)."""
    return n * (-(h0 + dt * wp.dot(vel, n)) * mass_over_dt2(w_inv, inv_dt2))


@wp.func
def skin_profile(u: wp.vec3, fwd: wp.vec3, n: wp.vec3, mu_back: float):
    """The direction profile g(θ) of a skin whose friction differs by direction, its first and second derivatives in
    θ, and e_θ = n × u, for the unit tangential direction ``u`` at angle θ from the head-ward tangent ``fwd`` (``n``
    the floor normal): g = 1 + (mu_back − 1) S(w), S(w) = 3w² − 2w³, w = (1 − cos θ) / 2, so 1 head-ward,
    (1 + mu_back) / 2 sideways, mu_back tail-ward. A cubic in cos θ: |v| g and |v|² g are convex for every
    mu_back > 0 (g + g'' >= min(1, mu_back), checked on a fine grid), so the friction of :func:`friction_force` is a
    monotone force with a symmetric PSD stiffness."""
    lat = wp.cross(n, fwd)
    a = wp.dot(u, fwd)  # cos θ
    b = wp.dot(u, lat)  # sin θ
    w = 0.5 * (1.0 - a)
    s1 = 6.0 * w * (1.0 - w)
    d = mu_back - 1.0
    g = 1.0 + d * w * w * (3.0 - 2.0 * w)
    return g, d * s1 * 0.5 * b, d * ((6.0 - 12.0 * w) * 0.25 * b * b + s1 * 0.5 * a), lat * a - fwd * b


@wp.func
def skin_scale(v: wp.vec3, fwd: wp.vec3, n: wp.vec3, mu_back: float) -> float:
    """g(θ) of :func:`skin_profile` for the tangential part of ``v`` (1 when it has none, or when ``mu_back`` is 1):
    the factor on both friction coefficients of a vertex moving that way (used where a landing vertex's friction is
    applied at position level, without a Newton stiffness)."""
    if mu_back == 1.0:
        return 1.0
    vt = v - n * wp.dot(v, n)
    speed = wp.length(vt)
    if not (speed > 0.0):
        return 1.0
    g, g1, g2, e = skin_profile(vt / speed, fwd, n, mu_back)
    return g


@wp.func
def friction_force(status: int, vt: wp.vec3, normal_force: float, mu_s: float, mu_k: float, mu_back: float,
                   fwd: wp.vec3, n: wp.vec3, slip_speed: float):
    """The floor's friction on a vertex on it moving at tangential velocity ``vt`` [m/s] under ``normal_force``
    [N]: (force [N]; its stiffness −∂f/∂v [N·s/m] on the tangent plane as a scalar times (I − n nᵀ − t tᵀ), and the
    unit direction t that excludes (the sliding direction; zero when stuck); and the rest of the stiffness as a
    symmetric PSD matrix, zero for isotropic friction).

    Isotropic (``mu_back`` 1, the paper's): stuck (static, ``status`` CONTACT_STUCK), f = −(mu_s F_n / ε) v_t, a
    stiff viscous force that reaches mu_s F_n at ε = ``slip_speed``, so a vertex held by friction creeps at most ~ε;
    one moving faster than ε has broken loose. Sliding (kinetic): f = −mu_k F_n v_t / |v_t|, whose derivative is
    (mu_k F_n / |v_t|)(I − t tᵀ) on the plane.

    A skin that grips by direction (``mu_back`` ≠ 1: tail-ward over head-ward; ``fwd`` the head-ward tangent, ``n``
    the floor normal): the friction is −∇D of the convex dissipation D = mu_k F_n |v| g(θ) sliding and
    (mu_s F_n / 2ε) |v|² g(θ) stuck (g of :func:`skin_profile`), the maximal-dissipation law of an anisotropic
    surface: along the slide it is g times the isotropic one, and a slide at an angle to the axis is also pushed
    toward the easier direction (−g' e_θ). Its stiffness is D's Hessian, so the Newton matrix stays symmetric and
    exact (a scaled coefficient without its derivative made the iteration cycle: half the substeps hit the step cap).
    """
    if not (normal_force > 0.0):
        return wp.vec3(0.0), 0.0, wp.vec3(0.0), wp.mat33(0.0)
    speed = wp.length(vt)
    if mu_back == 1.0:
        if status == CONTACT_STUCK:
            c = mu_s * normal_force / slip_speed
            return vt * (-c), c, wp.vec3(0.0), wp.mat33(0.0)
        if speed > 0.0:
            c = mu_k * normal_force / speed
            return vt * (-c), c, vt / speed, wp.mat33(0.0)
        return wp.vec3(0.0), 0.0, wp.vec3(0.0), wp.mat33(0.0)
    if not (speed > 0.0):
        if status == CONTACT_STUCK:
            # D's Hessian has no value at v = 0 (it depends on the direction): the mean of head-ward and tail-ward
            return wp.vec3(0.0), 0.0, wp.vec3(0.0), (wp.identity(n=3, dtype=float) - wp.outer(n, n)) * (
                mu_s * normal_force / slip_speed * 0.5 * (1.0 + mu_back))
        return wp.vec3(0.0), 0.0, wp.vec3(0.0), wp.mat33(0.0)
    u = vt / speed
    g, g1, g2, e = skin_profile(u, fwd, n, mu_back)
    if status == CONTACT_STUCK:
        c0 = mu_s * normal_force / slip_speed
        f = (vt * g + e * (0.5 * g1 * speed)) * (-c0)
        k = (wp.outer(u, u) * g + (wp.outer(u, e) + wp.outer(e, u)) * (0.5 * g1) + wp.outer(e, e) * (g + 0.5 * g2))
        return f, 0.0, wp.vec3(0.0), k * c0
    cn = mu_k * normal_force
    return (u * g + e * g1) * (-cn), 0.0, wp.vec3(0.0), wp.outer(e, e) * (cn / speed * wp.max(g + g2, 0.0))


@wp.func
def dof_projector(status: int, n: wp.vec3) -> wp.mat33:
    """The directions a vertex may move in a constrained Newton step: all (free), along the floor (on it), none (a
    vertex of infinite mass)."""
    if status == CONTACT_FIXED:
        return wp.mat33(0.0)
    if status == CONTACT_SLIDING or status == CONTACT_STUCK:
        return wp.identity(n=3, dtype=float) - wp.outer(n, n)
    return wp.identity(n=3, dtype=float)


@wp.struct
class BarHingeModel:
    """The model arrays the substep reads (shapes as :class:`warpworm.sim.model.Model`; "(R, ...)": R = 1 shared or W
    rows, read at row ``world % R``)."""

    inv_mass: wp.array2d(dtype=float)  # (R, V) [1/kg]
    gravity: wp.array(dtype=float)  # (R,) [m/s²] along −z
    damping: wp.array(dtype=float)  # (R,) linear velocity damping [1/s]
    edges: wp.array2d(dtype=wp.int32)  # (E, 2)
    rest_length: wp.array2d(dtype=float)  # (R, E) [m]
    bar_stiffness: wp.array2d(dtype=float)  # (R, E) EA [N]
    bar_stop_strain: wp.array2d(dtype=wp.vec2)  # (R, E) (shortened, stretched) stop strains
    bar_stop_stiffness: wp.array2d(dtype=float)  # (R, E) EA of the stop [N]
    hinges: wp.array2d(dtype=wp.int32)  # (H, 4)
    hinge_rest: wp.array2d(dtype=float)  # (R, H) [rad]
    hinge_length: wp.array2d(dtype=float)  # (R, H) [m]
    hinge_label: wp.array(dtype=wp.int32)  # (H,)
    hinge_stiffness: wp.array(dtype=float)  # (R,) k_α per metre of crease [N·m/rad/m]
    hinge_damping: wp.array(dtype=float)  # (R,) c_α per metre of crease [N·m·s/rad/m]
    fold_limit_stiffness: wp.array(dtype=float)  # (R,) NoFoldThrough barrier per metre [N·m/rad/m]
    anchor_vertex: wp.array(dtype=wp.int32)  # (A,)
    anchor_stiffness: wp.array2d(dtype=float)  # (R, A) [N/m]
    floor_incline: wp.array(dtype=float)  # (R,) [rad] about +y
    mu_static: wp.array(dtype=float)  # (R,)
    mu_kinetic: wp.array(dtype=float)  # (R,)
    friction_backward_ratio: wp.array(dtype=float)  # (R,) μ tail-ward over μ head-ward (1: isotropic)


@wp.struct
class SubstepOptions:
    """The solver's settings (:class:`warpworm.sim.simulator.Simulator`)."""

    dt: float  # substep [s]
    num_substeps: int  # substeps per launch
    newton: int  # Newton steps per substep at most (>= 2)
    newton_tol: float  # [m] a Newton step (the second or later) moving no vertex farther than this ends the substep
    refactor: int  # 1: assemble and factor the Hessian at every Newton step; 0: chord steps (module docstring)
    slip_speed: float  # static-friction regularisation ε [m/s]
    strain_limit: wp.array(dtype=float)  # (E,) |strain| beyond which a world explodes
    speed_limit: float  # [m/s] beyond which (or non-finite) a world explodes
    fold_tolerance: float  # [rad] beyond a crease's range: the world crumpled


@wp.struct
class BarHingeState:
    """The physical state the substep advances (shapes as :class:`warpworm.sim.model.State`)."""

    x: wp.array2d(dtype=wp.vec3)  # (W, V) [m]
    v: wp.array2d(dtype=wp.vec3)  # (W, V) [m/s]
    floor_force: wp.array2d(dtype=wp.vec3)  # (W, V) [N] the floor's force in the last substep
    bar_strain: wp.array2d(dtype=float)  # (W, E)
    crease_angle: wp.array2d(dtype=float)  # (W, H) [rad] unwrapped
    contact: wp.array2d(dtype=wp.int32)  # (W, V) CONTACT_*
    unstable: wp.array(dtype=wp.int32)  # (W,) 0, 1 exploded, 2 crumpled
    step_count: wp.array(dtype=wp.int32)  # (W,) substeps since t = 0


@wp.struct
class NewtonScratch:
    """The solver's own scratch (:class:`warpworm.sim.simulator.Simulator` owns it; its values mean nothing between
    launches, except ``delta``, which is zero there, and the counters)."""

    x_prev: wp.array2d(dtype=wp.vec3)  # (W, V) positions at the start of the substep [m]
    delta: wp.array2d(dtype=wp.vec3)  # (W, V) x − x̃ [m]
    hess: wp.array3d(dtype=wp.mat33)  # (W, V, B + 1) lower block band of the Newton matrix
    grad: wp.array2d(dtype=wp.vec3)  # (W, V) right-hand side, then the Newton step
    released: wp.array2d(dtype=wp.int32)  # (W, V) bit 0: it let go of the floor in this substep; above: its stick/slip switches
    newton_steps: wp.array(dtype=wp.int32)  # (W,) Newton steps taken, summed over substeps (a diagnostic counter)
    newton_capped: wp.array(dtype=wp.int32)  # (W,) substeps that took every step without meeting the tolerance
    newton_factors: wp.array(dtype=wp.int32)  # (W,) Newton steps that assembled and factored the Hessian


@wp.struct
class WorldCoefficients:
    """One world's parameter rows and scalars, read once per launch."""

    im_row: int
    rl_row: int
    ea_row: int
    hr_row: int
    hl_row: int
    ak_row: int
    ss_row: int  # bar_stop_strain's
    sk_row: int  # bar_stop_stiffness's
    gravity: wp.vec3  # [m/s²]
    damp: float  # 1 / (1 + c dt)
    k_hinge: float
    c_hinge: float
    k_limit: float
    floor_n: wp.vec3  # the floor's unit normal
    mu_s: float
    mu_k: float
    mu_back: float  # friction_backward_ratio
    floor_fwd: wp.vec3  # the floor's tangent along the worm's rest axis (+x tilted with the floor): head-ward
    dt: float
    inv_dt: float
    inv_dt2: float


@wp.func
def world_coefficients(m: BarHingeModel, world: int, dt: float) -> WorldCoefficients:
    c = WorldCoefficients()
    c.im_row = world % m.inv_mass.shape[0]
    c.rl_row = world % m.rest_length.shape[0]
    c.ea_row = world % m.bar_stiffness.shape[0]
    c.hr_row = world % m.hinge_rest.shape[0]
    c.hl_row = world % m.hinge_length.shape[0]
    c.ak_row = world % m.anchor_stiffness.shape[0]
    # the rows once per launch: an integer division per bar and Newton step cost ~1 µs per step
    c.ss_row = world % m.bar_stop_strain.shape[0]
    c.sk_row = world % m.bar_stop_stiffness.shape[0]
    c.gravity = wp.vec3(0.0, 0.0, -pw(m.gravity, world))
    c.damp = 1.0 / (1.0 + pw(m.damping, world) * dt)
    c.k_hinge = pw(m.hinge_stiffness, world)
    c.c_hinge = pw(m.hinge_damping, world)
    c.k_limit = pw(m.fold_limit_stiffness, world)
    beta = pw(m.floor_incline, world)
    c.floor_n = wp.vec3(-wp.sin(beta), 0.0, wp.cos(beta))
    c.mu_s = pw(m.mu_static, world)
    c.mu_k = pw(m.mu_kinetic, world)
    c.mu_back = pw(m.friction_backward_ratio, world)
    c.floor_fwd = wp.vec3(wp.cos(beta), 0.0, wp.sin(beta))
    c.dt = dt
    c.inv_dt = 1.0 / dt
    c.inv_dt2 = c.inv_dt * c.inv_dt
    return c


@wp.func
def inertia_terms(world: int, c: WorldCoefficients, m: BarHingeModel, with_hessian: bool, s: BarHingeState,
                  w: NewtonScratch):
    """Start ``grad`` (and the Hessian's band) with the inertia term M (x − x̃) / dt²."""
    nv = s.x.shape[1]
    bw = w.hess.shape[2] - 1
    eye = wp.identity(n=3, dtype=float)
    for i in range(nv):
        m_dt2 = mass_over_dt2(m.inv_mass[c.im_row, i], c.inv_dt2)
        w.grad[world, i] = w.delta[world, i] * m_dt2  # delta is 0 for a vertex of infinite mass
        if with_hessian:
            # m/dt² on the diagonal in every direction, also the fixed ones (keeps the matrix definite; their rows
            # are decoupled by the projection and their update is zero)
            w.hess[world, i, 0] = eye * m_dt2
            for k in range(1, bw + 1):
                w.hess[world, i, k] = wp.mat33(0.0)


@wp.func
def friction_terms(world: int, c: WorldCoefficients, slip_speed: float, with_hessian: bool, s: BarHingeState,
                   w: NewtonScratch):
    """Add the floor friction of every vertex on the floor (:func:`friction_force`) to ``grad`` and, with the
    Hessian, its stiffness to the diagonal blocks."""
    eye = wp.identity(n=3, dtype=float)
    for i in range(s.x.shape[1]):
        st = s.contact[world, i]
        if st == CONTACT_SLIDING or st == CONTACT_STUCK:
            f, kf, t, k_skin = vertex_friction(world, i, c, slip_speed, s, w)
            w.grad[world, i] = w.grad[world, i] - f
            if with_hessian:
                w.hess[world, i, 0] = w.hess[world, i, 0] + (
                    eye - wp.outer(c.floor_n, c.floor_n) - wp.outer(t, t)) * (kf * c.inv_dt) + k_skin * c.inv_dt


@wp.func
def vertex_friction(world: int, i: int, c: WorldCoefficients, slip_speed: float, s: BarHingeState,
                    w: NewtonScratch):
    """:func:`friction_force` of vertex ``i`` on the floor at its current Newton iterate (velocity v' + (x − x̃)/dt,
    normal force of ``floor_force``)."""
    vel = s.v[world, i] + w.delta[world, i] * c.inv_dt
    vt = vel - c.floor_n * wp.dot(vel, c.floor_n)
    return friction_force(s.contact[world, i], vt, wp.dot(s.floor_force[world, i], c.floor_n), c.mu_s, c.mu_k,
                          c.mu_back, c.floor_fwd, c.floor_n, slip_speed)


@wp.func
def bar_terms(world: int, c: WorldCoefficients, m: BarHingeModel, strain_limit: wp.array(dtype=float),
              with_hessian: bool, s: BarHingeState, w: NewtonScratch) -> int:
    """Add every bar's spring (and a waist bar's stop) to ``grad`` / the Hessian; record its strain.
    Returns 1 if a bar is strained beyond its ``strain_limit`` (or non-finite), else 0."""
    eye = wp.identity(n=3, dtype=float)
    for e in range(m.edges.shape[0]):
        a = m.edges[e, 0]
        b = m.edges[e, 1]
        d = s.x[world, a] - s.x[world, b]
        length = wp.length(d)
        l0 = m.rest_length[c.rl_row, e]
        strain = (length - l0) / l0
        s.bar_strain[world, e] = strain
        if not (wp.abs(strain) < strain_limit[e]):  # also catches NaN
            return 1
        n = d / length
        ka = m.bar_stiffness[c.ea_row, e] / l0
        f = n * (ka * (length - l0))
        k_axial = ka
        # a soft waist bar strained past its stops (−ε_c shortened, +ε_t stretched) turns rigid: the sheet's panels,
        # which the soft bar stands for, bend only so far (without them a hard squeeze flattens the waist triangles
        # into slivers, whose crease gradients blow up, or pinches the waist through the axis)
        stops = m.bar_stop_strain[c.ss_row, e]
        stop = wp.where(strain < 0.0, -stops[0], stops[1])
        l_stop = l0 * (1.0 + stop)
        k_trans = ka * wp.max(0.0, 1.0 - l0 / length)
        if wp.where(strain < 0.0, strain < stop, strain > stop):
            ks = m.bar_stop_stiffness[c.sk_row, e] / l0
            f = f + n * (ks * (length - l_stop))
            k_axial = k_axial + ks
            k_trans = k_trans + ks * wp.max(0.0, 1.0 - l_stop / length)  # the stop's tension, as the bar's
        w.grad[world, a] = w.grad[world, a] + f
        w.grad[world, b] = w.grad[world, b] - f
        if with_hessian:
            nn = wp.outer(n, n)
            # the compressive geometric stiffness is dropped (keeps the matrix positive definite)
            kb = k_axial * nn + k_trans * (eye - nn)
            band_add_block(world, w.hess, a, a, kb)
            band_add_block(world, w.hess, b, b, kb)
            band_add_block(world, w.hess, a, b, -kb)
    return 0


@wp.func
def wing_contact_terms(world: int, n: wp.vec3, len2: float, p0: wp.vec3, p1: wp.vec3, p2: wp.vec3, a: int, b: int,
                       c: int, lh: float, with_hessian: bool, w: NewtonScratch):
    """Add a hinge wing's panel contact barrier (:func:`~.common.wing_contact_of_normal`; tip ``a`` at ``p0``, hinge
    ``b``–``c``, ``n`` the wing's normal, ``len2`` the hinge's squared length) to ``grad`` / the Hessian."""
    f, ga, gb, gc, kappa = wing_contact_of_normal(n, len2, p0, p1, p2, lh)
    if kappa > 0.0:
        w.grad[world, a] = w.grad[world, a] + ga * f
        w.grad[world, b] = w.grad[world, b] + gb * f
        w.grad[world, c] = w.grad[world, c] + gc * f
        if with_hessian:
            band_add_gauss_newton3(world, w.hess, ALL_ROWS, kappa, a, b, c, ga, gb, gc)


@wp.func
def crease_terms(world: int, c: WorldCoefficients, m: BarHingeModel, with_hessian: bool, s: BarHingeState,
                 w: NewtonScratch):
    """Add every crease's spring, its damping, its NoFoldThrough barrier and its wings' panel contact barrier to
    ``grad`` / the Hessian (``crease_angle`` holds the angles at the start of the substep: damping, unwrapping)."""
    for h in range(m.hinges.shape[0]):
        i0 = m.hinges[h, 0]
        i1 = m.hinges[h, 1]
        i2 = m.hinges[h, 2]
        i3 = m.hinges[h, 3]
        x0 = s.x[world, i0]
        x1 = s.x[world, i1]
        x2 = s.x[world, i2]
        x3 = s.x[world, i3]
        psi, g0, g1, g2, g3, n1, n2, len2 = dihedral_angle_gradient_and_normals(x0, x1, x2, x3)
        prev = s.crease_angle[world, h]
        phi = prev + wrap_angle(psi - prev)
        lh = m.hinge_length[c.hl_row, h]
        torque = lh * (c.k_hinge * (phi - m.hinge_rest[c.hr_row, h]) + c.c_hinge * c.inv_dt * (phi - prev))
        stiff = lh * (c.k_hinge + c.c_hinge * c.inv_dt)
        lo, hi = fold_range(m.hinge_label[h])
        if phi < lo or phi > hi:
            torque += c.k_limit * lh * (phi - wp.where(phi < lo, lo, hi))
            stiff += c.k_limit * lh
        w.grad[world, i0] = w.grad[world, i0] + g0 * torque
        w.grad[world, i1] = w.grad[world, i1] + g1 * torque
        w.grad[world, i2] = w.grad[world, i2] + g2 * torque
        w.grad[world, i3] = w.grad[world, i3] + g3 * torque
        if with_hessian:
            # Gauss–Newton: the angle's curvature term (torque ∇²φ) is dropped
            band_add_gauss_newton4(world, w.hess, ALL_ROWS, stiff, i0, i1, i2, i3, g0, g1, g2, g3)
        # the wings' normals are the dihedral's own: n1 = (x1 − x0) × (x2 − x0), n2 = (x2 − x3) × (x1 − x3)
        wing_contact_terms(world, n1, len2, x0, x1, x2, i0, i1, i2, lh, with_hessian, w)
        wing_contact_terms(world, n2, len2, x3, x2, x1, i3, i2, i1, lh, with_hessian, w)


@wp.func
def anchor_terms(world: int, c: WorldCoefficients, m: BarHingeModel, anchor_target: wp.array2d(dtype=wp.vec3),
                 with_hessian: bool, s: BarHingeState, w: NewtonScratch):
    """Add every anchor's spring ½ k |x − target|² to ``grad`` / the Hessian."""
    eye = wp.identity(n=3, dtype=float)
    for an in range(m.anchor_vertex.shape[0]):
        pv = m.anchor_vertex[an]
        ka = m.anchor_stiffness[c.ak_row, an]
        if ka > 0.0:
            w.grad[world, pv] = w.grad[world, pv] + (s.x[world, pv] - anchor_target[world, an]) * ka
            if with_hessian:
                band_add_block(world, w.hess, pv, pv, eye * ka)


@wp.func
def project_on_contacts(world: int, c: WorldCoefficients, m: BarHingeModel, s: BarHingeState, w: NewtonScratch):
    """The Newton step restricted to each vertex's allowed directions: block (u, v) -> P_u B P_v; the removed
    directions of a diagonal block get m/dt² back (keeps the matrix definite; their update is zero)."""
    nv = s.x.shape[1]
    bw = w.hess.shape[2] - 1
    eye = wp.identity(n=3, dtype=float)
    for u in range(nv):
        su = s.contact[world, u]
        for band in range(bw + 1):
            vv = u - band
            if vv >= 0:
                sv = s.contact[world, vv]
                if su != CONTACT_FREE or sv != CONTACT_FREE:
                    pu = dof_projector(su, c.floor_n)
                    blk = pu * w.hess[world, u, band] * dof_projector(sv, c.floor_n)
                    if band == 0:
                        blk = blk + (eye - pu) * mass_over_dt2(m.inv_mass[c.im_row, u], c.inv_dt2)
                    w.hess[world, u, band] = blk


@wp.func
def elastic_terms(world: int, c: WorldCoefficients, m: BarHingeModel, opt: SubstepOptions,
                  anchor_target: wp.array2d(dtype=wp.vec3), with_hessian: bool, s: BarHingeState,
                  w: NewtonScratch) -> int:
    """The inertia, bars, creases and anchors of ``grad`` (and the unprojected Hessian): everything but the floor
    friction, which is tangential and so not in the floor's normal balance that :func:`update_contacts` reads.
    Returns 1 if a bar is strained beyond its ``strain_limit`` (per bar; or non-finite), else 0."""
    inertia_terms(world, c, m, with_hessian, s, w)
    if bar_terms(world, c, m, opt.strain_limit, with_hessian, s, w) != 0:
        return 1
    crease_terms(world, c, m, with_hessian, s, w)
    anchor_terms(world, c, m, anchor_target, with_hessian, s, w)
    return 0


@wp.func
def assemble(world: int, c: WorldCoefficients, m: BarHingeModel, opt: SubstepOptions,
             anchor_target: wp.array2d(dtype=wp.vec3), s: BarHingeState, w: NewtonScratch) -> int:
    """Gradient ∂Φ/∂x of the substep's objective (inertia, bars, creases, anchors, floor friction) into
    ``w.grad[world]`` and its Gauss–Newton Hessian projected on each vertex's allowed directions into
    ``w.hess[world]``. Returns 1 if a bar is strained beyond its ``strain_limit`` (or non-finite), else 0."""
    if elastic_terms(world, c, m, opt, anchor_target, True, s, w) != 0:
        return 1
    friction_terms(world, c, opt.slip_speed, True, s, w)
    project_on_contacts(world, c, m, s, w)
    return 0


@wp.func
def predict(world: int, c: WorldCoefficients, m: BarHingeModel, slip_speed: float,
            f_ext: wp.array2d(dtype=wp.vec3), s: BarHingeState, w: NewtonScratch) -> int:
    """Predict x̃ and start the Newton iteration at :func:`newton_start`: a vertex on the floor (touching at the end of
    the last substep, or carried below it: :func:`starting_contact`) starts stuck on it, unless it is moving off it:
    every substep first tries static friction, the Coulomb test of :func:`update_contacts` lets go where it cannot
    hold."""
    dt = c.dt
    changed = int(0)
    for i in range(s.x.shape[1]):
        w_inv = m.inv_mass[c.im_row, i]
        vel = wp.vec3(0.0)
        v_old = s.v[world, i]
        if w_inv > 0.0:
            # linear damping on the velocity carried over, not on this substep's forces (damping them too
            # would lower a hanging worm's weight on its anchors by the factor 1 / (1 + c dt))
            vel = v_old * c.damp + dt * (c.gravity + f_ext[world, i] * w_inv)
        p = s.x[world, i]
        w.x_prev[world, i] = p
        w.released[world, i] = 0
        s.v[world, i] = vel
        h0 = wp.dot(p, c.floor_n)
        st = starting_contact(w_inv, s.contact[world, i], vel, v_old, h0, c.floor_n, dt, slip_speed)
        if (st == CONTACT_STUCK or st == CONTACT_SLIDING) and s.contact[world, i] == CONTACT_FREE:
            s.floor_force[world, i] = landing_floor_force(h0, vel, c.floor_n, dt, w_inv, c.inv_dt2)
        start = newton_start(st, vel, v_old, h0, c.floor_n, c.inv_dt)
        if st != s.contact[world, i]:
            changed = 1
        s.contact[world, i] = st
        s.x[world, i] = p + dt * start
        w.delta[world, i] = (start - vel) * dt
    return changed


MAX_STICK_SLIP_SWITCHES = wp.constant(6)
"""Stick/slip switches a vertex may make in one substep; past them it is held (stuck) for the rest of it."""

RELEASED_LET_GO = wp.constant(1)  # bit 0 of ``released``: the vertex let go of the floor in this substep
RELEASED_SWITCH = wp.constant(2)  # the count of its stick/slip switches in this substep, in the bits above


@wp.func
def stick_slip_status(st: int, vt: wp.vec3, ff: wp.vec3, fn: float, n: wp.vec3, slip_speed: float, released: int):
    """The stick/slip rule of a vertex on the floor between Newton steps: a stuck vertex whose viscous static friction
    (mu_s F_n,old / ε)|v_t| exceeds what mu_s F_n can hold (the normal force now known) broke loose; a sliding one
    whose motion reversed against its last floor force ``ff`` (normal + friction; kinetic friction stopped it) or fell below half the slip
    speed sticks. Returns (status, released). After MAX_STICK_SLIP_SWITCHES switches in a substep a vertex is held
    (stuck; a sliding one makes that one more switch) for the rest of it: two neighbours can otherwise take turns
    (one held, carrying the load that breaks the other loose, then the reverse) and keep the iteration from
    converging, which a skin that grips 2x tail-ward did in half of its substeps; held, a vertex creeps at a few times
    the slip speed (~2e-5 m/s) for the rest of that substep. The limit applies to isotropic friction too: the
    presets never reach it (unchanged to the last digit), other worlds may. (The rule's direction factor cancels:
    a skin scales mu_s F_n,old and mu_s F_n alike.)"""
    vt_len = wp.length(vt)
    new_st = st
    if st == CONTACT_STUCK and vt_len * wp.dot(ff, n) > slip_speed * fn:
        new_st = CONTACT_SLIDING
    elif st == CONTACT_SLIDING and (wp.dot(vt, ff) > 0.0 or vt_len < 0.5 * slip_speed):
        new_st = CONTACT_STUCK
    if new_st != st:
        if released / RELEASED_SWITCH >= MAX_STICK_SLIP_SWITCHES:
            new_st = CONTACT_STUCK
        else:
            released = released + RELEASED_SWITCH
    return new_st, released


@wp.func
def update_contacts(world: int, c: WorldCoefficients, m: BarHingeModel, slip_speed: float, s: BarHingeState,
                    w: NewtonScratch) -> int:
    """Between Newton steps (``w.grad`` holds ∂Φ/∂x at the current x): the floor's normal force at each contact is
    n · ∂Φ/∂x there (what holds the vertex against the rest of the implicit step); a contact the floor would have to
    pull lets go; a stuck vertex faster than the slip speed broke loose, a sliding one whose motion reversed (kinetic
    friction stopped it) or fell below half the slip speed sticks; a free vertex the last step put below the floor
    lands. A vertex lets go at most once per substep (``w.released``): one that landed again stays on the floor, with no
    normal force while the floor would have to pull, so that a vertex with ~zero normal force cannot cycle land / let
    go / land between Newton steps and keep the iteration from converging. Returns CONTACTS_LANDED if a vertex landed
    (x moved), else CONTACTS_CHANGED if one changed its status
    (the Newton matrix's projection changed), else 0."""
    dt = c.dt
    changed = int(0)
    for i in range(s.x.shape[1]):
        st = s.contact[world, i]
        if st == CONTACT_FIXED:
            continue
        vel0 = s.v[world, i]
        vel = vel0 + w.delta[world, i] * c.inv_dt
        vn = wp.dot(vel, c.floor_n)
        if st == CONTACT_FREE:
            depth = -(wp.dot(w.x_prev[world, i], c.floor_n) + dt * vn)
            if depth > 0.0:
                vel = vel + c.floor_n * (depth * c.inv_dt)
                s.x[world, i] = w.x_prev[world, i] + vel * dt
                w.delta[world, i] = (vel - vel0) * dt
                # stuck: it lets go at the next update if static friction cannot hold it
                s.contact[world, i] = CONTACT_STUCK
                s.floor_force[world, i] = c.floor_n * (depth * mass_over_dt2(m.inv_mass[c.im_row, i], c.inv_dt2))
                changed = CONTACTS_LANDED
            continue
        fn = wp.dot(w.grad[world, i], c.floor_n)  # friction is tangential: not in the normal balance
        if not (fn > 0.0):
            if (w.released[world, i] & RELEASED_LET_GO) == 0:
                s.contact[world, i] = CONTACT_FREE
                s.floor_force[world, i] = wp.vec3(0.0)
                w.released[world, i] = w.released[world, i] | RELEASED_LET_GO
                changed = wp.max(changed, CONTACTS_CHANGED)
                continue
            fn = 0.0  # it let go once already: held on the floor, without normal force (nor friction)
        vt = vel - c.floor_n * vn
        new_st, rel = stick_slip_status(st, vt, s.floor_force[world, i], fn, c.floor_n, slip_speed,
                                        w.released[world, i])
        s.contact[world, i] = new_st
        w.released[world, i] = rel
        if new_st != st:
            changed = wp.max(changed, CONTACTS_CHANGED)
        f, kf, t, k_skin = friction_force(s.contact[world, i], vt, fn, c.mu_s, c.mu_k, c.mu_back, c.floor_fwd,
                                          c.floor_n, slip_speed)
        s.floor_force[world, i] = c.floor_n * fn + f
    return changed


@wp.func
def newton_solve(world: int, c: WorldCoefficients, factor: bool, s: BarHingeState, w: NewtonScratch) -> float:
    """Solve H dx = −grad restricted to the allowed directions, leaving −dx in ``w.grad``; ``factor``: factor the
    freshly assembled H first, else reuse the factor left in ``w.hess`` (a chord step). Returns max |dx| [m] (1e30
    for a non-finite step). :func:`newton_apply` applies it."""
    nv = s.x.shape[1]
    bw = w.hess.shape[2] - 1
    for i in range(nv):
        g = w.grad[world, i]
        st = s.contact[world, i]
        if st != CONTACT_FREE:
            g = dof_projector(st, c.floor_n) * g
        w.grad[world, i] = g
    if factor:
        band_cholesky_factor(world, nv, bw, w.hess)
    band_cholesky_solve(world, nv, bw, w.hess, w.grad)
    step = float(0.0)
    for i in range(nv):
        length = wp.length(w.grad[world, i])
        if not (length < 1.0e30):
            length = 1.0e30  # a non-finite step is no convergence (wp.max would drop a NaN)
        step = wp.max(step, length)
    return step


@wp.func
def newton_apply(world: int, s: BarHingeState, w: NewtonScratch):
    """x += dx and (x − x̃) += dx for the step :func:`newton_solve` left in ``w.grad`` (as −dx)."""
    for i in range(s.x.shape[1]):
        dx = -w.grad[world, i]
        s.x[world, i] = s.x[world, i] + dx
        w.delta[world, i] = w.delta[world, i] + dx


@wp.func
def finish_substep(world: int, c: WorldCoefficients, m: BarHingeModel, opt: SubstepOptions, s: BarHingeState,
                   w: NewtonScratch):
    """The floor once more (vertices that reached it in the last step) and v = v' + (x − x̃) / dt.
    Returns (1 if a vertex is faster than ``speed_limit`` (or non-finite), else 0; 1 if a vertex changed its contact
    status, else 0)."""
    dt = c.dt
    bad = int(0)
    changed = int(0)
    for i in range(s.x.shape[1]):
        # v = v' + (x − x̃) / dt with x − x̃ summed at its own precision (see floor_landing)
        vel = s.v[world, i] + w.delta[world, i] * c.inv_dt
        w.delta[world, i] = wp.vec3(0.0)
        p0 = w.x_prev[world, i]
        st = s.contact[world, i]
        if st == CONTACT_FREE:
            # a vertex that reaches the floor only in the last step: position-level contact and friction
            k_dir = skin_scale(vel, c.floor_fwd, c.floor_n, c.mu_back)
            p, vel, st, depth = floor_landing(p0, vel, c.floor_n, c.mu_s * k_dir, c.mu_k * k_dir, dt)
            s.floor_force[world, i] = c.floor_n * (depth * mass_over_dt2(m.inv_mass[c.im_row, i], c.inv_dt2))
        elif st == CONTACT_STUCK or st == CONTACT_SLIDING:
            vn = wp.dot(vel, c.floor_n)
            vel = vel + c.floor_n * (wp.max(vn, -wp.dot(p0, c.floor_n) * c.inv_dt) - vn)
            vt = vel - c.floor_n * wp.dot(vel, c.floor_n)
            fn = wp.dot(s.floor_force[world, i], c.floor_n)
            f, kf, t, k_skin = friction_force(st, vt, fn, c.mu_s, c.mu_k, c.mu_back, c.floor_fwd, c.floor_n,
                                              opt.slip_speed)
            s.floor_force[world, i] = c.floor_n * fn + f
        else:
            vel = wp.vec3(0.0)  # infinite mass
            st = CONTACT_FREE
        if not (wp.length(vel) < opt.speed_limit):  # NaN fails every comparison
            bad = 1
        s.x[world, i] = p0 + vel * dt
        s.v[world, i] = vel
        if st != s.contact[world, i]:
            changed = 1
        s.contact[world, i] = st
    return bad, changed


@wp.func
def update_crease_angles(world: int, m: BarHingeModel, fold_tolerance: float, s: BarHingeState) -> int:
    """Unwrap every crease's angle to the end of the substep. Returns 1 if one left its NoFoldThrough range by more
    than ``fold_tolerance``, or one of its wings collapsed (:func:`~.common.crease_at_substep_end`): the sheet
    crumpled; else 0."""
    crumpled = int(0)
    for h in range(m.hinges.shape[0]):
        phi, flagged = crease_at_substep_end(s.crease_angle[world, h], s.x[world, m.hinges[h, 0]],
                                             s.x[world, m.hinges[h, 1]], s.x[world, m.hinges[h, 2]],
                                             s.x[world, m.hinges[h, 3]], m.hinge_label[h], fold_tolerance)
        s.crease_angle[world, h] = phi
        if flagged:
            crumpled = 1
    return crumpled


@wp.kernel
def implicit_step(
    m: BarHingeModel,
    opt: SubstepOptions,
    f_ext: wp.array2d(dtype=wp.vec3),
    anchor_target: wp.array2d(dtype=wp.vec3),
    s: BarHingeState,
    w: NewtonScratch,
):
    """``opt.num_substeps`` implicit-Euler substeps of length ``opt.dt`` [s] of one world (module docstring).
    Launch dim (W,). ``f_ext (W, V)`` the step's magnetic force on each vertex [N]; ``anchor_target (W, A)`` [m].
    A world flagged unstable is frozen (skipped) from then on."""
    world = wp.tid()
    if s.unstable[world] != 0:
        return
    c = world_coefficients(m, world, opt.dt)
    # the factor the last substep of this launch made serves this substep's first step as a chord step if no contact
    # changed status since: that saves the assembly of the Hessian and its factorization in every other substep
    # (module docstring). Only within a launch: a launch's result never depends on what ran before it.
    carried = bool(False)  # the last substep of this launch made a factor of the contact set it ended with
    have_factor = bool(False)  # this substep starts on it
    for sub in range(opt.num_substeps):
        statuses_changed = predict(world, c, m, opt.slip_speed, f_ext, s, w)
        have_factor = carried and statuses_changed == 0
        carried = bool(False)
        bad = int(0)
        last_step = float(1.0e30)
        stalled = bool(False)
        converged = bool(False)
        for it in range(opt.newton):
            # assemble and factor the Hessian, else a chord step; a chord step that did not halve the last step
            # (e.g. kinetic friction's stiffness mu_k F_n / |v_t| gone stale) refactors the next
            fresh = (it == 0 and not have_factor) or opt.refactor != 0 or stalled
            if it == 0:
                if fresh:
                    bad = assemble(world, c, m, opt, anchor_target, s, w)
                else:
                    bad = elastic_terms(world, c, m, opt, anchor_target, False, s, w)
                    if bad == 0:
                        friction_terms(world, c, opt.slip_speed, False, s, w)
            else:
                # one assembly serves both the floor's normal forces and the Newton step: friction, the one term
                # that depends on the contacts, is added after they are updated
                bad = elastic_terms(world, c, m, opt, anchor_target, fresh, s, w)
                if bad != 0:
                    break
                change = update_contacts(world, c, m, opt.slip_speed, s, w)
                if change == CONTACTS_LANDED or (change != 0 and not fresh):
                    fresh = True  # x moved, or the chord's factor has a stale projection: assemble anew
                    bad = assemble(world, c, m, opt, anchor_target, s, w)
                else:
                    friction_terms(world, c, opt.slip_speed, fresh, s, w)
                    if fresh:
                        project_on_contacts(world, c, m, s, w)
            if bad != 0:
                break
            w.newton_steps[world] = w.newton_steps[world] + 1
            if fresh:
                w.newton_factors[world] = w.newton_factors[world] + 1
            step = newton_solve(world, c, fresh, s, w)
            if fresh:
                # a substep begun on a carried factor that had to refactor begins the next with a fresh one
                carried = opt.refactor == 0 and not have_factor
            if not fresh and not (step < CHORD_CONTRACTION * last_step):
                # a chord step that would not contract (its factor gone stale: kinetic friction's stiffness, or
                # near-rigid bars turned) is not taken: the next step assembles and factors at this same x
                stalled = True
                continue
            newton_apply(world, s, w)
            # converged: after one contact update at least, and after a chord step only with the iterate's error
            # left (θ/(1 − θ) times the step, θ < ½ its contraction) below STOP_ERROR times the tolerance: what the
            # steps of a fresh factor (θ ~ 0.07) met anyway, and what keeps a carried factor's slower contraction
            # from ending substeps as inaccurately as a 10x looser tolerance would
            theta = step / last_step
            if it >= 1 and step < opt.newton_tol and (
                    fresh or step * theta < STOP_ERROR * opt.newton_tol * (1.0 - theta)):
                converged = True
                break
            stalled = False
            last_step = step
        if bad == 0 and not converged:
            w.newton_capped[world] = w.newton_capped[world] + 1  # the cap, not the tolerance, ended it
        if bad == 0:
            bad, statuses_changed = finish_substep(world, c, m, opt, s, w)
            if statuses_changed != 0:
                carried = False  # the factor's projection is another contact set's
            crumpled = update_crease_angles(world, m, opt.fold_tolerance, s)
            if bad == 0 and crumpled != 0:
                # a crease folded through its range by more than the tolerance: the sheet crumpled (flag 2)
                freeze_world(world, s.x.shape[1], s.x, s.v, w.x_prev, w.delta, s.unstable)
                s.unstable[world] = WORLD_CRUMPLED
                return
        if bad != 0:
            freeze_world(world, s.x.shape[1], s.x, s.v, w.x_prev, w.delta, s.unstable)
            return
        s.step_count[world] = s.step_count[world] + 1
