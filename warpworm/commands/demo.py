"""``warpworm demo``: the default worm with its three IPMs and an EPM above it, the wrench on each IPM under both
magnet models, the worm mesh (GLB) and the field picture (PNG)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from warpworm.analysis.field_plot import render_field_picture
from warpworm.commands.common import check_positive, device_option, first_run_notice, refuse
from warpworm.data import export_json as strict_json
from warpworm.physics import crease, magnets
from warpworm.physics.params import MAGNET_SLOTS, WormParams

HELP = "Build the default worm and magnets, print the magnetic wrench on each IPM under both models, write GLB + PNG."


def add_arguments(parser) -> None:
    parser.add_argument("--out", default="out/demo", help="output folder (created) [default: out/demo]")
    parser.add_argument("--height", type=float, default=0.03, help="EPM centre height above the floor [m]")
    parser.add_argument("--device", default=None, help="Warp device (cpu, cuda:0); default: Warp's default")
    parser.add_argument("--json", action="store_true", help="print the wrenches as JSON only")


def demo_scene(height: float):
    """The default worm (WormParams defaults) and the poses of its 4 magnets (EPM, tail, centre, head IPM).

    The EPM stands vertically (south pole down, moment +z) between the centre and head IPMs, as in the peristaltic
    gait (paper §III-A). Returns (pattern, magnets, positions (4, 3) [m], rotations (4, 3, 3)).
    """

    p = WormParams()
    pattern = crease.build_worm(p.a, p.b, p.n_units, l0=p.l0)
    ipm_pos, ipm_rot = crease.mount_poses(pattern)
    epm_x = ipm_pos[1, 0] + 0.4 * (ipm_pos[2, 0] - ipm_pos[1, 0])  # a bit closer to the centre IPM
    positions = np.vstack([[epm_x, ipm_pos[1, 1], height], ipm_pos])
    rotations = np.concatenate([np.eye(3)[None], ipm_rot])
    mags = [magnets.Cuboid(p.epm_size, moment=p.epm_moment)]
    mags += [magnets.Cylinder(p.ipm_diameter, p.ipm_thickness, moment=m) for m in np.asarray(p.ipm_moment)]
    return pattern, mags, positions, rotations


def main(args) -> int:
    out = Path(args.out)
    try:
        check_positive(height=args.height)
        args.device = device_option(args.device)
        if out.exists() and not out.is_dir():
            raise ValueError(f"--out: got '{out}'; expected a folder (it is a file)")
    except ValueError as exc:
        return refuse(exc)

    first_run_notice(("warpworm.kernels.magnet_wrench",))
    out.mkdir(parents=True, exist_ok=True)
    pattern, mags, pos, rot = demo_scene(args.height)
    results = {}
    for model in ("analytic", "dipoles"):
        F, T = magnets.world_wrenches(mags, pos[None], rot[None], model=model, device=args.device)
        results[model] = {"force_N": F[0].tolist(), "torque_Nm": T[0].tolist()}
    glb = crease.export_mesh(pattern, out / "worm.glb")
    png = render_field_picture(out / "field.png")
    if args.json:
        print(strict_json.dumps({"magnets": list(MAGNET_SLOTS), "wrenches": results, "files": [str(glb), str(png)]}))
        return 0
    print(f"worm: {pattern.num_vertices} vertices, {pattern.num_triangles} facets, {pattern.num_edges} bars, "
          f"{pattern.num_hinges} hinges; EPM centre at {np.round(pos[0] * 1e3, 2)} mm")
    print(f"{'magnet':<11}{'model':<10}{'Fx [N]':>11}{'Fy [N]':>11}{'Fz [N]':>11}"
          f"{'Tx [mN·m]':>12}{'Ty [mN·m]':>12}{'Tz [mN·m]':>12}")
    for slot in range(1, 4):
        for model, r in results.items():
            f, t = np.array(r["force_N"][slot]), np.array(r["torque_Nm"][slot]) * 1e3
            print(f"{MAGNET_SLOTS[slot]:<11}{model:<10}" + "".join(f"{v:11.4f}" for v in f)
                  + "".join(f"{v:12.4f}" for v in t))
    print(f"wrote {glb}\nwrote {png}")
    return 0
