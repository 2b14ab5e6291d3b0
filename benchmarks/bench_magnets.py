"""Magnet wrenches for W worlds of the worm (one EPM bar + three IPM disks, all pairs), both models, vs magpylib.

Each world: EPM 10×10×40 mm cuboid (3.6 A·m²) above three 10 mm × 1 mm axial disks (0.0707 A·m²), the worm's
layout with small random perturbations; the net force and torque on all four magnets from the other three
(12 ordered pair wrenches per world), by one ``launch_world_wrenches`` call (6 unordered pair evaluations, each
pair's reaction the other magnet's share); ``epm`` = False rows write the EPM's wrench as zero (``epm_wrench=False``,
what the dynamics uses; the same work).

Columns: ``ms_per_call`` (process CPU time, best of repeats, after a warm-up that includes compilation: Warp runs a
CPU launch on the calling thread, and on a shared machine CPU time leaves out the time the scheduler gave to other
processes, which wall time would count; the best repeat is the least disturbed one), ``us_per_world``,
``pairs_per_s`` (point-dipole pair interactions evaluated per second, 'dipoles' model: 9,648 per world at 64/cm³,
each serving both magnets), ``vs_nbody`` (that rate over the plain inverse-square n-body kernel's, timed in launches
interleaved with the row's repeats; ``vs_dipole_nbody``: over the plain point-dipole force+field n-body row of the
same run), ``field_evals_per_s`` ('analytic', the closed-form row: source-field evaluations at quadrature points).
magpylib rows run ``getFT`` for the same 12 pair wrenches per world (meshing 1000 cells per target, ~1e-4
agreement) for small W only; ``magpylib_est`` rows extrapolate that per-world cost linearly to larger W and are
labelled as estimates.

A ``warpworm, IPM poses NaN`` row per model (W = 16) times the call on an exploded world's poses: NaN wrenches
at once (before, the quadrature ran on NaN: ~13 ms a world).

A before/after comparison runs this file on each of two checkouts (docs/magnets.md keeps the measured ones).
"""

from __future__ import annotations

import time

import numpy as np
import warp as wp

from warpworm import quiet_warp
from warpworm.physics import magnets as mg
from warpworm.transforms import matrix_to_quat_wxyz, quat_wxyz_to_xyzw

NBODY_BODIES = 2048
NOTES = ("pairs_per_s: point-dipole pair interactions evaluated per second ('dipoles'; today 9,648 per world at "
         "64/cm³, each unordered magnet pair once, its reaction the other magnet's share, so epm=False costs the same; "
         "vs_nbody: that rate over "
         "the inverse-square n-body kernel's, timed interleaved with the row (vs_dipole_nbody: over the point-dipole "
         "force+field n-body row). magpylib_est rows are "
         "linear extrapolations of the measured magpylib per-world cost, not measurements.")


@wp.kernel
def _nbody_inverse_square(pos: wp.array(dtype=wp.vec3), mass: wp.array(dtype=float), acc: wp.array(dtype=wp.vec3)):
    """The simplest n-body kernel: acceleration of body i from all bodies (softened inverse square)."""
    i = wp.tid()
    p = pos[i]
    a = wp.vec3(0.0)
    for j in range(pos.shape[0]):
        r = pos[j] - p
        d2 = wp.dot(r, r) + 1.0e-6
        inv = 1.0 / wp.sqrt(d2)
        a += (mass[j] * inv * inv * inv) * r
    acc[i] = a


@wp.kernel
def _nbody_dipoles(pos: wp.array(dtype=wp.vec3), moment: wp.array(dtype=wp.vec3), force: wp.array(dtype=wp.vec3),
                   field: wp.array(dtype=wp.vec3)):
    """A plain point-dipole n-body kernel: force on dipole i and field at i from all other dipoles (the pair term of
    the 'dipoles' model, written directly with per-body moments)."""
    i = wp.tid()
    p = pos[i]
    mt = moment[i]
    f = wp.vec3(0.0)
    b = wp.vec3(0.0)
    for j in range(pos.shape[0]):
        if j != i:
            r = p - pos[j]
            ms = moment[j]
            inv_r2 = 1.0 / wp.dot(r, r)
            inv_r = wp.sqrt(inv_r2)
            inv_r3 = inv_r * inv_r2
            inv_r5 = inv_r3 * inv_r2
            a = wp.dot(r, ms)
            c = wp.dot(r, mt)
            b += 1.0e-7 * (3.0 * a * inv_r5 * r - inv_r3 * ms)
            f += (3.0e-7 * inv_r5) * (c * ms + a * mt + (wp.dot(ms, mt) - 5.0 * a * c * inv_r2) * r)
    force[i] = f
    field[i] = b


def _nbody_call(device, n=1024):
    """A launch of the inverse-square n-body kernel on ``n`` bodies, and its pair count (the interleaved reference)."""
    rng = np.random.default_rng(1)
    pos = wp.array(rng.normal(size=(n, 3)).astype(np.float32) * 0.05, dtype=wp.vec3, device=device)
    mass = wp.array(rng.uniform(0.5, 1.5, n).astype(np.float32), dtype=float, device=device)
    acc = wp.zeros(n, dtype=wp.vec3, device=device)

    def call():
        wp.launch(_nbody_inverse_square, dim=n, inputs=[pos, mass, acc], device=device)
        wp.synchronize_device(device)

    return call, n * n


def _time_interleaved(fn, ref, repeats):
    """Best-of-repeats times of ``fn`` and ``ref``, alternating, so both see the same share of a busy machine."""
    fn()
    ref()
    ts, tr = [], []
    for _ in range(repeats):
        t0 = time.process_time()
        fn()
        ts.append(time.process_time() - t0)
        t0 = time.process_time()
        ref()
        tr.append(time.process_time() - t0)
    return float(np.min(ts)), float(np.min(tr))


def _nbody_rows(device, repeats=5):
    """Pair rates of the two plain n-body kernels on NBODY_BODIES bodies (N² pairs per launch), this run."""
    rng = np.random.default_rng(0)
    n = NBODY_BODIES
    pos = wp.array(rng.normal(size=(n, 3)).astype(np.float32) * 0.05, dtype=wp.vec3, device=device)
    mass = wp.array(rng.uniform(0.5, 1.5, n).astype(np.float32), dtype=float, device=device)
    moment = wp.array(rng.normal(size=(n, 3)).astype(np.float32) * 1e-3, dtype=wp.vec3, device=device)
    out_a = wp.zeros(n, dtype=wp.vec3, device=device)
    out_b = wp.zeros(n, dtype=wp.vec3, device=device)
    rows = []
    for name, kernel, args in (("inverse-square", _nbody_inverse_square, [pos, mass, out_a]),
                               ("point-dipole F+B", _nbody_dipoles, [pos, moment, out_a, out_b])):
        def call():
            wp.launch(kernel, dim=n, inputs=args, device=device)
            wp.synchronize_device(device)

        t = _time(call, repeats)
        rows.append({"impl": "n-body reference", "model": name, "W": n, "ms_per_call": 1e3 * t,
                     "pairs_per_s": n * n / t})
    return rows


def _worlds(W, seed=0):
    from scipy.spatial.transform import Rotation  # optional dependency: scipy (the test extra)

    rng = np.random.default_rng(seed)
    pos = np.zeros((W, 4, 3))
    rot = np.zeros((W, 4, 3, 3))
    theta = rng.uniform(0, np.pi, W)
    pos[:, 0] = np.stack([rng.uniform(-0.02, 0.02, W), rng.uniform(-0.005, 0.005, W), rng.uniform(0.04, 0.06, W)], 1)
    rot[:, 0] = Rotation.from_euler("y", (np.pi / 2 - theta)[:, None]).as_matrix()
    for s, sign in ((1, -1), (2, 1), (3, -1)):
        pos[:, s] = np.stack([(s - 2) * 0.027 + rng.normal(size=W) * 1e-3, rng.normal(size=W) * 1e-3,
                              np.full(W, 0.008)], 1)
        tilt = Rotation.from_euler("xyz", rng.normal(size=(W, 3)) * 0.2)
        rot[:, s] = (tilt * Rotation.from_euler("y", sign * np.pi / 2)).as_matrix()
    return pos, rot


def _magnets():
    epm = mg.Cuboid((0.01, 0.01, 0.04), moment=3.6)
    ipm = mg.Cylinder(0.01, 0.001, moment=0.9e6 * np.pi * 0.005**2 * 0.001)
    return [epm, ipm, ipm, ipm]


def _time(fn, repeats):
    fn()  # warm-up (compiles on first use)
    ts = []
    for _ in range(repeats):
        t0 = time.process_time()
        fn()
        ts.append(time.process_time() - t0)
    return float(np.min(ts))


def _dipole_pairs_per_world(magnets, density, targets=range(4)):
    """Point-dipole pairs of the wrench on ``targets`` from all the other magnets (each magnet's own sum over its
    sources, as a baseline revision's kernel computes them)."""
    n = [len(mg.dipole_grid(m, density)) for m in magnets]
    return sum(n[i] * n[j] for i in targets for j in range(4) if i != j)


def _analytic_evals_per_world(pos, rot, magnets, quad_order, max_panels):
    """Closed-form field evaluations of today's kernel with every pair in closed form (``far_field=False``) in world
    0: each unordered pair once, the lower index the source (mirrors the panel rule of magnet_fields.py)."""
    total = 0
    for i in range(4):
        for j in range(i):
            s, t = magnets[j], magnets[i]
            Rrel = rot[0, j].T @ rot[0, i]
            trel = rot[0, j].T @ (pos[0, i] - pos[0, j])
            half = 0.5 * s.size if s.shape == 0 else np.array([s.size[0] / 2, s.size[0] / 2, s.size[2] / 2])

            def gap(p, hd):
                return np.linalg.norm(np.maximum(np.abs(p) - half, 0)) - hd

            def panels(ext, g):
                return max_panels if g <= ext / max_panels else min(max_panels, max(1, int(np.ceil(ext / g))))

            if t.shape == 0:
                for k in range(3):
                    if t.moment[k] == 0:
                        continue
                    u, v = (k + 1) % 3, (k + 2) % 3
                    for sign in (1, -1):
                        g = gap(trel + Rrel[:, k] * sign * t.size[k] / 2, 0.5 * np.hypot(t.size[u], t.size[v]))
                        total += panels(t.size[u], g) * panels(t.size[v], g) * quad_order**2
            else:
                R = t.size[0] / 2
                for sign in (1, -1):
                    g = gap(trel + Rrel[:, 2] * sign * t.size[2] / 2, R)
                    total += panels(R, g) * quad_order * 3 * quad_order * panels(2 * R, g)
    return total


def _magpylib_world(magnets, pos, rot, meshing=1000):
    import magpylib as magpy  # optional dependency: magpylib (the test extra)
    from scipy.spatial.transform import Rotation  # optional dependency: scipy (the test extra)

    def make(m, p, R):
        o = Rotation.from_matrix(R)
        if m.shape == 1:
            return magpy.magnet.Cylinder(polarization=m.polarization, dimension=(m.size[0], m.size[2]), position=p,
                                         orientation=o)
        return magpy.magnet.Cuboid(polarization=m.polarization, dimension=m.size, position=p, orientation=o)

    for w in range(len(pos)):
        objs = [make(m, pos[w, k], rot[w, k]) for k, m in enumerate(magnets)]
        for i in range(4):
            # the force on target i from the three others, as one getFT call (sums over sources)
            sources = [objs[j] for j in range(4) if j != i]
            magpy.getFT(sources, objs[i], pivot="centroid", meshing=meshing)


def _launcher(model_arr, arrays, device, epm, far=True):
    """One world-wrench call (:func:`warpworm.physics.magnets.launch_world_wrenches`, the pair kernels), with or
    without ``epm_wrench``; ``far`` = the ring rules."""
    a = arrays
    scratch = mg.pair_wrench_scratch(*a["pos"].shape, device)

    def call():
        mg.launch_world_wrenches(model_arr, a["shape"], a["size"], a["moment"], a["pos"], a["rot"], a["force_out"],
                                 a["torque_out"], a["density"], device, epm_wrench=epm, far_field=far,
                                 pair_scratch=scratch)
        wp.synchronize_device(device)

    return call


def run(quick: bool = False) -> list[dict]:
    quiet_warp()
    wp.init()
    device = wp.get_device("cpu")
    sizes = [1, 16, 256] if quick else [1, 16, 256, 1024, 4096]
    magnets = _magnets()
    density = 64e6
    pairs_per_world = _dipole_pairs_per_world(magnets, density)
    pairs_evaluated = pairs_per_world // 2  # each unordered pair once (its reaction the other magnet's share): 9,648
    variants = [("warpworm", True), ("warpworm", False)]
    rows = _nbody_rows(device)
    ref_call, ref_pairs = _nbody_call(device)
    for model in ("dipoles", "analytic"):
        model_arr = wp.array([mg.MODELS[model]], dtype=wp.int32, device=device)
        for W in sizes:
            pos, rot = _worlds(W)
            q = quat_wxyz_to_xyzw(matrix_to_quat_wxyz(rot.reshape(-1, 3, 3))).reshape(W, 4, 4)
            arrays = dict(
                shape=wp.array(np.array([[m.shape for m in magnets]], np.int32), dtype=wp.int32, device=device),
                size=wp.array(np.array([[m.size for m in magnets]], np.float32), dtype=wp.vec3, device=device),
                moment=wp.array(np.array([[m.moment for m in magnets]], np.float32), dtype=wp.vec3,
                                device=device),
                pos=wp.array(pos.astype(np.float32), dtype=wp.vec3, device=device),
                rot=wp.array(q.astype(np.float32), dtype=wp.quat, device=device),
                force_out=wp.zeros((W, 4), dtype=wp.vec3, device=device),
                torque_out=wp.zeros((W, 4), dtype=wp.vec3, device=device),
                density=wp.array([density], dtype=wp.float32, device=device),
            )
            repeats = 3 if W * 12 > 3000 else 10
            closed_t = None
            # 'analytic' also once with every pair in closed form (no far-field ring rule): the rule's gain
            runs = [(impl, epm, True) for impl, epm in variants]
            if model == "analytic":
                runs.insert(0, ("warpworm closed form", False, False))
            for impl, epm, far in runs:
                call = _launcher(model_arr, arrays, device, epm, far)
                if model == "dipoles":
                    t, t_ref = _time_interleaved(call, ref_call, max(repeats, 5))
                else:
                    t = _time(call, repeats)
                row = {"impl": impl, "model": model, "epm": epm, "W": W, "ms_per_call": 1e3 * t,
                       "us_per_world": 1e6 * t / W, "pair_wrenches_per_s": (12 if epm else 9) * W / t}
                if not far:
                    closed_t = t
                if far and not epm and closed_t is not None and impl == "warpworm":
                    row["vs_closed_form"] = closed_t / t
                if model == "dipoles":
                    row["pairs_per_s"] = pairs_evaluated * W / t
                    row["vs_nbody"] = row["pairs_per_s"] / (ref_pairs / t_ref)
                elif not far:
                    row["field_evals_per_s"] = _analytic_evals_per_world(
                        pos, rot, magnets, mg.DEFAULT_QUAD_ORDER, mg.DEFAULT_MAX_PANELS) * W / t
                rows.append(row)
            if W == 16:  # an exploded world's NaN poses (the simulator no longer steps it, a snapshot still asks)
                nan_pos = pos.astype(np.float32)
                nan_pos[:, 1:] = np.nan
                t = _time(_launcher(model_arr, {**arrays, "pos": wp.array(nan_pos, dtype=wp.vec3, device=device)},
                                    device, False), repeats)
                rows.append({"impl": "warpworm, IPM poses NaN", "model": model, "epm": False, "W": W,
                             "ms_per_call": 1e3 * t, "us_per_world": 1e6 * t / W})
    # the point-dipole reference once more, after (the faster of the two measurements: conservative on a shared
    # machine); vs_nbody was measured against an inverse-square launch interleaved with each row's repeats
    for ref, again in zip(rows[:2], _nbody_rows(device)):
        if again["pairs_per_s"] > ref["pairs_per_s"]:
            ref.update(again)
    for row in rows[2:]:
        if "pairs_per_s" in row and row["model"] == "dipoles":
            row["vs_dipole_nbody"] = row["pairs_per_s"] / rows[1]["pairs_per_s"]
    # magpylib: the same 12 pair wrenches per world, measured at small W
    try:
        import magpylib  # noqa: F401
    except ImportError:
        return rows
    measured = [1, 16] if not quick else [1, 4]
    per_world = None
    for W in measured:
        pos, rot = _worlds(W)
        t = _time(lambda: _magpylib_world(magnets, pos, rot), 1 if W > 1 else 3)
        per_world = t / W
        rows.append({"impl": "magpylib getFT", "model": "exact (mesh 1000)", "W": W, "ms_per_call": 1e3 * t,
                     "us_per_world": 1e6 * t / W, "pair_wrenches_per_s": 12 * W / t})
    for W in [s for s in sizes if s > max(measured)]:
        rows.append({"impl": "magpylib_est", "model": "exact (mesh 1000)", "W": W, "ms_per_call": 1e3 * per_world * W,
                     "us_per_world": 1e6 * per_world, "pair_wrenches_per_s": 12 / per_world})
    return rows
