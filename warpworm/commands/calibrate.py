"""``warpworm calibrate``: fit a magnet's dipole moment to a measured force–distance table (paper §IV-A)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from warpworm.analysis import calibration
from warpworm.commands.common import check_positive, refuse

HELP = "fit a magnet's dipole moment to a force-distance table (CSV: gap_m, force_N), least squares"


def add_arguments(parser) -> None:
    parser.add_argument("table", help="CSV with columns gap_m, force_N (attraction of two magnets, unlike poles facing)")
    parser.add_argument("--shape", default="cube", choices=["cube", "cuboid", "cylinder"], help="magnet shape")
    parser.add_argument("--size", type=float, nargs="+", default=[0.01],
                        help="cube edge, or cuboid x y z extents [m] (default 0.01)")
    parser.add_argument("--diameter", type=float, help="cylinder diameter [m]")
    parser.add_argument("--height", type=float, help="cylinder height [m]")
    parser.add_argument("--target-moment", type=float, default=None,
                        help="moment of a known second magnet of the same shape [A·m²]; default: identical pair, both fitted")
    parser.add_argument("--model", default="analytic", choices=["analytic", "dipoles"], help="magnet model")
    parser.add_argument("--density", type=float, default=64e6, help="dipoles per m³ for --model dipoles (64e6 = 64/cm³)")
    parser.add_argument("--relative", action="store_true", help="weight points by 1/F (fit relative errors)")


def _table(path):
    """The CSV's gaps and forces, refused (ValueError naming the file, row and value) unless it holds at least two
    rows of finite numbers with gaps > 0 (magnets apart) and forces > 0 (attraction)."""

    if not Path(path).is_file():
        raise ValueError(f"table: got '{path}'; expected a CSV file with columns gap_m, force_N (not a file)")
    try:
        gaps, forces = calibration.read_table(path)
    except UnicodeDecodeError:
        raise ValueError(f"table: got '{path}'; expected a text CSV with columns gap_m, force_N") from None
    if len(gaps) < 2:
        raise ValueError(f"table: got {len(gaps)} row(s) of numbers in '{path}'; expected at least 2 (gap_m, force_N)")
    for name, v, what in (("gap_m", gaps, "finite gaps > 0 [m] (the magnets apart)"),
                          ("force_N", forces, "finite attraction forces > 0 [N]")):
        bad = np.flatnonzero(~(np.isfinite(v) & (v > 0)))
        if bad.size:
            raise ValueError(f"table: {name} in row {int(bad[0]) + 1} of the numbers of '{path}': got {v[bad[0]]}; "
                             f"expected {what}")
    return gaps, forces


def main(args) -> int:
    try:
        if len(args.size) not in (1, 3):
            raise ValueError(f"--size: got {len(args.size)} values; expected 1 (edge) or 3 (x y z extents) [m]")
        check_positive(**{"size": min(args.size), "diameter": args.diameter, "height": args.height,
                          "density": args.density})
        if args.target_moment is not None:
            check_positive(target_moment=args.target_moment)
        if args.shape == "cylinder" and (args.diameter is None or args.height is None):
            raise ValueError("--shape cylinder: expected --diameter and --height [m]")
        size = args.size[0] if len(args.size) == 1 else args.size
        unit = calibration._as_magnet(None, args.shape, size, args.diameter, args.height, (0.0, 0.0, 1.0))
        table = _table(args.table)
        target = None if args.target_moment is None else unit.with_moment(args.target_moment)
        fit = calibration.fit_moment(table, unit, target=target, model=args.model, density=args.density,
                                     relative=args.relative)
    except ValueError as exc:
        return refuse(exc)
    extents = ", ".join(f"{1e3 * float(v):g}" for v in unit.size)
    print(f"table: {args.table} ({len(fit.gaps)} points); magnet: {args.shape} [{extents}] mm")
    print(fit.report())
    return 0
