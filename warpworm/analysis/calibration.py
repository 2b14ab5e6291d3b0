"""Magnet-strength calibration (paper §IV-A): fit a dipole moment to a measured force–distance table.

The paper measured the attraction of two identical N52 cubes (1 cm³, unlike poles facing) against the gap and
varied the simulated moment until the curves matched (0.9 A·m² at 64 dipoles/cm³). Here that is a least-squares
fit. The force between two uniformly magnetized magnets is bilinear in their moments, F = m_s m_t f(gap) with f
the force for unit moments, so

- identical magnets (``target=None``): F = c f with c = m², linear in c;
- a known target magnet: F = m_s (m_t f), linear in m_s.

Either way one column of model forces is computed (one batched kernel launch at unit moment) and the scale is the
linear least-squares solution (``numpy.linalg.lstsq``), optionally weighted by 1/F (``relative=True``) so the
far, weak points count as much as the near ones. The residual is reported as RMS [N] and relative to the RMS force.

Geometry: the source sits at the origin magnetized along its own +z (or ``direction``); the target sits on the +z
axis with the given face-to-face gap, magnetized the same way, so the poles facing each other are unlike and
positive forces mean attraction.
"""

from __future__ import annotations

import csv
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from warpworm.physics import magnets as mg


@dataclass
class MomentFit:
    """Result of :func:`fit_moment`. SI units."""

    moment: float
    """Fitted dipole moment magnitude of the source [A·m²] (of each magnet when the pair is identical)."""
    polarization: float
    """The same as a polarization J = mu0 m / V [T]."""
    magnet: mg.Magnet
    """The source magnet with the fitted moment."""
    residual_rms: float
    """RMS of measured − predicted force [N]."""
    residual_rel: float
    """residual_rms / RMS of the measured forces."""
    max_rel_error: float
    """Largest |measured − predicted| / |measured| over the table."""
    gaps: np.ndarray = field(repr=False)
    """Face-to-face gaps of the table [m], shape (K,)."""
    measured: np.ndarray = field(repr=False)
    """Measured attraction [N], shape (K,)."""
    predicted: np.ndarray = field(repr=False)
    """Fitted model's attraction [N], shape (K,)."""
    model: str = "analytic"

    def report(self) -> str:
        lines = [
            f"model: {self.model}",
            f"fitted moment: {self.moment:.6g} A·m²  (polarization J = {self.polarization:.6g} T, "
            f"{self.moment / self.magnet.volume * 1e-6:.6g} A·m² per cm³)",
            f"residual: RMS {self.residual_rms:.4g} N, relative {100 * self.residual_rel:.3g} %, "
            f"max point {100 * self.max_rel_error:.3g} %",
            f"{'gap [mm]':>10} {'measured [N]':>14} {'fitted [N]':>12} {'error %':>9}",
        ]
        for g, m, p in zip(self.gaps, self.measured, self.predicted):
            lines.append(f"{1e3 * g:10.3f} {m:14.6g} {p:12.6g} {100 * (p - m) / m if m else float('nan'):9.3f}")
        return "\n".join(lines)


def read_table(path) -> tuple[np.ndarray, np.ndarray]:
    """Read a force–distance CSV with columns ``gap_m, force_N`` (header optional; extra columns ignored)."""
    path = Path(path)
    gaps, forces = [], []
    with path.open(newline="") as fh:
        rows = list(csv.reader(fh))
    if not rows:
        raise ValueError(f"{path}: empty table, expected columns gap_m, force_N")
    start = 0
    header = [c.strip().lower() for c in rows[0]]
    ig, iF = 0, 1
    try:
        float(rows[0][0])
    except (ValueError, IndexError):
        start = 1
        if "gap_m" in header and "force_n" in header:
            ig, iF = header.index("gap_m"), header.index("force_n")
    for k, row in enumerate(rows[start:], start=start + 1):
        if not row or row[0].strip().startswith("#"):
            continue
        try:
            gaps.append(float(row[ig]))
            forces.append(float(row[iF]))
        except (ValueError, IndexError):
            raise ValueError(f"{path}:{k}: expected two numbers gap_m, force_N, got {row!r}") from None
    return np.asarray(gaps), np.asarray(forces)


def write_table(path, gaps, forces) -> Path:
    """Write a ``gap_m, force_N`` CSV."""
    path = Path(path)
    with path.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["gap_m", "force_N"])
        for g, f in zip(gaps, forces):
            w.writerow([f"{g:.9g}", f"{f:.9g}"])
    return path


def _as_magnet(magnet, shape, size, diameter, height, direction) -> mg.Magnet:
    direction = np.asarray(direction, dtype=np.float64)
    if direction.shape != (3,) or not np.linalg.norm(direction) > 0:
        raise ValueError(f"direction={direction!r}: expected a non-zero 3-vector")
    direction = direction / np.linalg.norm(direction)
    if magnet is not None:
        return magnet.with_moment(direction)
    shape = shape.lower()
    if shape in ("cube", "cuboid", "bar"):
        return mg.Cuboid(size, moment=direction)
    if shape in ("cylinder", "disk", "disc"):
        if diameter is None or height is None:
            raise ValueError(f"shape={shape!r}: expected diameter= and height= [m]")
        return mg.Cylinder(diameter, height, moment=direction)
    raise ValueError(f"shape={shape!r}: expected 'cube'/'cuboid' or 'cylinder'")


def pair_forces(source: mg.Magnet, target: mg.Magnet, gaps, model="analytic", density=mg.DEFAULT_DENSITY):
    """Attraction [N] (positive = attractive) between coaxial ``source`` and ``target`` at face gaps [m], (K,).

    Both stacked along the source's +z, same orientation (unlike poles facing when both point along +z).
    """
    gaps = np.asarray(gaps, dtype=np.float64)
    if np.any(gaps <= 0):
        raise ValueError(f"gaps must be positive (magnets may not touch or overlap), got min {gaps.min()}")
    z = 0.5 * source.size[2] + gaps + 0.5 * target.size[2]
    pt = np.stack([np.zeros_like(z), np.zeros_like(z), z], axis=1)
    eye = np.broadcast_to(np.eye(3), (len(z), 3, 3))
    F, _ = mg.wrench(source, target, (np.zeros(3), np.eye(3)), (pt, eye), model=model, density=density)
    return -np.atleast_2d(F)[:, 2]


def fit_moment(
    table,
    magnet: mg.Magnet | None = None,
    *,
    shape: str = "cube",
    size=0.01,
    diameter: float | None = None,
    height: float | None = None,
    direction=(0.0, 0.0, 1.0),
    target: mg.Magnet | None = None,
    model: str = "analytic",
    density: float = mg.DEFAULT_DENSITY,
    relative: bool = False,
) -> MomentFit:
    """Fit the dipole moment of a magnet to a force–distance table by linear least squares.

    Args:
        table: CSV path (``gap_m, force_N``) or a pair of arrays (gaps [m], attraction forces [N]).
        magnet: the magnet's geometry (its moment is ignored); or give ``shape`` ('cube' | 'cylinder') with
            ``size`` (edge or (x, y, z) extents [m]) or ``diameter`` and ``height`` [m].
        direction: magnetization direction in the magnet frame (default +z, the stacking axis).
        target: a second, *known* magnet (moment included); None = two identical magnets, both fitted.
        model: 'analytic' or 'dipoles' (then ``density`` [1/m³] matters, as in the paper's fit).
        relative: weight each point by 1/|F| (fits relative rather than absolute errors).

    Returns:
        :class:`MomentFit` with the moment [A·m²], polarization [T] and residuals.
    """
    if isinstance(table, (str, Path)):
        gaps, forces = read_table(table)
    else:
        gaps, forces = (np.asarray(a, dtype=np.float64) for a in table)
    if gaps.shape != forces.shape or gaps.ndim != 1 or len(gaps) < 1:
        raise ValueError(f"table: expected equal-length 1-D gaps and forces, got {gaps.shape} and {forces.shape}")
    unit = _as_magnet(magnet, shape, size, diameter, height, direction)
    tgt = unit if target is None else target
    f_unit = pair_forces(unit, tgt, gaps, model=model, density=density)  # force at m_s = 1 (and m_t = 1 if identical)
    w = 1.0 / np.abs(forces) if relative else np.ones_like(forces)
    (c,), *_ = np.linalg.lstsq((w * f_unit)[:, None], w * forces, rcond=None)
    if target is None:
        if c <= 0:
            raise ValueError("table: the fitted m² is not positive; are the forces attractive (positive)?")
        m = float(np.sqrt(c))
    else:
        m = float(c)
    predicted = c * f_unit
    res = forces - predicted
    rms = float(np.sqrt(np.mean(res**2)))
    fitted = unit.with_moment(unit.moment * m)
    return MomentFit(
        moment=m,
        polarization=float(mg.MU0 * m / unit.volume),
        magnet=fitted,
        residual_rms=rms,
        residual_rel=rms / float(np.sqrt(np.mean(forces**2))),
        max_rel_error=float(np.max(np.abs(res) / np.maximum(np.abs(forces), 1e-300))),
        gaps=gaps,
        measured=forces,
        predicted=predicted,
        model=model,
    )
