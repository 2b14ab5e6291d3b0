"""``warpworm field``: the field around a bar magnet under both magnet models (the paper's Fig. 2)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from warpworm.analysis.field_plot import render_field_picture
from warpworm.commands.common import check_positive, refuse
from warpworm.physics import magnets as mg

HELP = "draw the field around a 10x10x40 mm bar magnet, dipole model (1 and 64 per cm³) beside the exact field"


def add_arguments(parser) -> None:
    parser.add_argument("--out", default="out/field", help="output folder (default out/field)")
    parser.add_argument("--densities", type=float, nargs="+", default=[1.0, 64.0],
                        help="dipole densities to draw, per cm³ (default 1 64)")
    parser.add_argument("--moment", type=float, default=3.6, help="bar moment along its long axis [A·m²]")


def main(args) -> int:
    out = Path(args.out)
    try:
        check_positive(densities=min(args.densities))
        if not np.isfinite(args.moment):
            raise ValueError(f"--moment: got {args.moment}; expected a finite moment [A*m^2]")
        if out.exists() and not out.is_dir():
            raise ValueError(f"--out: got '{out}'; expected a folder (it is a file)")
    except ValueError as exc:
        return refuse(exc)
    dens = tuple(d * 1e6 for d in args.densities)
    path = render_field_picture(out / "field.png", moment=args.moment, densities=dens)
    # a few numbers beside the picture: error of the dipole model on the bar's axis and beside it
    bar = mg.Cuboid((0.01, 0.01, 0.04), moment=args.moment)
    pts = np.array([[0, 0, 0.021], [0, 0, 0.025], [0, 0, 0.03], [0, 0, 0.04], [0.006, 0, 0], [0.01, 0, 0],
                    [0.02, 0, 0]])
    exact = mg.field(bar, (np.zeros(3), np.eye(3)), pts)
    print(f"{'point [mm]':>18} {'|B| exact [mT]':>15} " + " ".join(f"{f'err {d:g}/cm3':>12}" for d in args.densities))
    for k, p in enumerate(pts):
        errs = []
        for d in dens:
            b = mg.field(bar, (np.zeros(3), np.eye(3)), p[None], model="dipoles", density=d)[0]
            errs.append(np.linalg.norm(b - exact[k]) / np.linalg.norm(exact[k]))
        print(f"{'(' + ', '.join(f'{v:g}' for v in 1e3 * p) + ')':>18} {1e3 * np.linalg.norm(exact[k]):15.3f} "
              + " ".join(f"{100 * e:11.3f}%" for e in errs))
    print(f"wrote {path}")
    return 0
