"""``warpworm calibrate``: fit a magnet's dipole moment to a measured force–distance table (paper §IV-A)."""

from __future__ import annotations

HELP = "fit a magnet's dipole moment to a force-distance table (CSV: gap_m, force_N), least squares"


def add_arguments(parser) -> None:
    parser.add_argument("table", help="CSV with columns gap_m, force_N (attraction of two magnets, unlike poles facing)")
    parser.add_argument("--shape", default="cube", choices=["cube", "cuboid", "cylinder"], help="magnet shape")
    parser.add_argument("--size", type=float, nargs="+", default=[0.01],
                        help="cuboid edge, or x y z extents [m] (default 0.01)")
    parser.add_argument("--diameter", type=float, help="cylinder diameter [m]")
    parser.add_argument("--height", type=float, help="cylinder height [m]")
    parser.add_argument("--target-moment", type=float, default=None,
                        help="moment of a known second magnet of the same shape [A·m²]; default: identical pair, both fitted")
    parser.add_argument("--model", default="analytic", choices=["analytic", "dipoles"], help="magnet model")
    parser.add_argument("--density", type=float, default=64e6, help="dipoles per m³ for --model dipoles (64e6 = 64/cm³)")
    parser.add_argument("--relative", action="store_true", help="weight points by 1/F (fit relative errors)")


def main(args) -> int:
    from warpworm.analysis import calibration

    size = args.size[0] if len(args.size) == 1 else args.size
    if len(args.size) not in (1, 3):
        print(f"--size: expected 1 or 3 values, got {len(args.size)}")
        return 2
    unit = calibration._as_magnet(None, args.shape, size, args.diameter, args.height, (0.0, 0.0, 1.0))
    target = None if args.target_moment is None else unit.with_moment(args.target_moment)
    fit = calibration.fit_moment(args.table, unit, target=target, model=args.model, density=args.density,
                                 relative=args.relative)
    print(f"table: {args.table} ({len(fit.gaps)} points); magnet: {args.shape} {list(unit.size)} m")
    print(fit.report())
    return 0
