"""Magnet construction and fields: the closed forms against magpylib, the dipole grids against NumPy."""

import numpy as np
import pytest

from warpworm.physics import magnets as mg

magpy = pytest.importorskip("magpylib")
Rotation = pytest.importorskip("scipy.spatial.transform").Rotation

MU0 = 4e-7 * np.pi
I3 = np.eye(3)


# ---------------------------------------------------------------------------------------------------------------------
# construction
# ---------------------------------------------------------------------------------------------------------------------


def test_moment_and_polarization_agree():
    cube = mg.Cuboid(0.01, moment=0.9)
    assert np.allclose(cube.moment, [0, 0, 0.9])
    assert np.allclose(cube.polarization, [0, 0, 1.1310], atol=1e-4)  # DESIGN-NOTES: J = 1.1310 T
    disk = mg.Cylinder(0.01, 0.001, polarization=(0.0, 1.0, 0.0))
    assert np.allclose(disk.moment, [0, 1.0 / mg.MU0 * np.pi * 0.005**2 * 0.001, 0])
    bar = mg.Cuboid((0.01, 0.01, 0.04), polarization="N52")
    assert np.allclose(bar.polarization, [0, 0, 1.44])
    assert mg.Cuboid(0.01, polarization="n42").polarization[2] == pytest.approx(1.29)


@pytest.mark.parametrize(
    "call, words",
    [
        (lambda: mg.Cuboid(0.01), ["moment", "polarization", "exactly one"]),
        (lambda: mg.Cuboid(0.01, moment=1, polarization=1), ["exactly one"]),
        (lambda: mg.Cuboid((0.01, -0.01, 0.01), moment=1), ["size", "-0.01", "positive"]),
        (lambda: mg.Cuboid((0.01, 0.01), moment=1), ["size", "three"]),
        (lambda: mg.Cylinder(0.0, 0.001, moment=1), ["diameter", "positive"]),
        (lambda: mg.Cylinder(0.01, 0.001, polarization="N99"), ["polarization", "N99", "N52"]),
        (lambda: mg.Cylinder(0.01, 0.001, moment=(1, 2)), ["moment", "3-vector"]),
    ],
)
def test_bad_arguments_name_what_is_wrong(call, words):
    with pytest.raises(ValueError) as err:
        call()
    for w in words:
        assert w in str(err.value)


def test_bad_model_and_pose():
    cube = mg.Cuboid(0.01, moment=0.9)
    with pytest.raises(ValueError, match="model"):
        mg.wrench(cube, cube, (np.zeros(3), I3), ((0, 0, 0.02), I3), model="charges")
    with pytest.raises(ValueError, match="rotation"):
        mg.wrench(cube, cube, (np.zeros(3), 2 * I3), ((0, 0, 0.02), I3))


# ---------------------------------------------------------------------------------------------------------------------
# closed-form fields vs magpylib
# ---------------------------------------------------------------------------------------------------------------------


def _points_away_from_edges(magnet, n, rng, scale=0.03):
    """Random points outside/inside the magnet but at least 5 % of its size from any edge or face."""
    pts = rng.normal(size=(4 * n, 3)) * scale
    half = 0.5 * magnet.size
    q = np.abs(pts)
    if magnet.shape == mg.SHAPE_CYLINDER:
        rho = np.hypot(pts[:, 0], pts[:, 1])
        d_side = np.abs(rho - half[0])
        d_cap = np.abs(q[:, 2] - half[2])
        ok = (d_side > 0.05 * half[0]) & (d_cap > 0.05 * half[2])
    else:
        ok = np.all(np.abs(q - half) > 0.05 * half, axis=1)
    return pts[ok][:n]


@pytest.mark.parametrize("J", [(0.0, 0.0, 1.2), (0.3, -0.5, 1.1), (1.0, 0.2, 0.0)])
def test_cuboid_field_matches_magpylib(J):
    rng = np.random.default_rng(0)
    m = mg.Cuboid((0.01, 0.02, 0.04), polarization=J)
    ref = magpy.magnet.Cuboid(polarization=J, dimension=(0.01, 0.02, 0.04))
    pts = _points_away_from_edges(m, 1500, rng)
    # a rotated, shifted pose exercises the world -> magnet frame transform
    R = Rotation.from_euler("xyz", [0.3, -1.1, 2.0]).as_matrix()
    t = np.array([0.01, -0.02, 0.005])
    ref.position, ref.orientation = t, Rotation.from_matrix(R)
    world = pts @ R.T + t
    B = mg.field(m, (t, R), world)
    Bref = ref.getB(world)
    err = np.linalg.norm(B - Bref, axis=1) / np.linalg.norm(Bref, axis=1)
    assert err.max() < 1e-4, err.max()


@pytest.mark.parametrize("J", [(0.0, 0.0, 1.2), (0.3, -0.5, 1.1), (1.0, 0.2, 0.0)])
def test_cuboid_field_on_face_planes_and_edge_lines(J):
    """Observers exactly on the planes of the faces, on the lines of the edges and on the axes (outside the magnet),
    in the magnet's own frame: where atan2 terms sit on their branch cut and the log arguments are smallest."""
    half = np.array([0.005, 0.01, 0.02])
    m = mg.Cuboid(2 * half, polarization=J)
    ref = magpy.magnet.Cuboid(polarization=J, dimension=2 * half)
    pts = []
    for sx in (-1, 0, 1):
        for sy in (-1, 0, 1):
            for sz in (-1, 0, 1):
                for far in (1.5, 3.0):
                    for k in range(3):  # one coordinate pushed out of the box, the others on a plane or axis
                        p = np.array([sx, sy, sz], float) * half
                        if p[k] == 0:
                            p[k] = far * half[k]
                        else:
                            p[k] *= far
                        pts.append(p)
    pts = np.unique(np.array(pts, dtype=np.float32), axis=0).astype(np.float64)
    B = mg.field(m, (np.zeros(3), I3), pts)
    Bref = ref.getB(pts)
    err = np.linalg.norm(B - Bref, axis=1) / np.linalg.norm(Bref, axis=1)
    assert err.max() < 1e-4, (err.max(), pts[err.argmax()])


@pytest.mark.parametrize("J", [(0.0, 0.0, 1.2), (0.6, 0.8, 0.0), (0.4, 0.2, 1.0)])
@pytest.mark.parametrize("dims", [(0.01, 0.001), (0.006, 0.02)])
def test_cylinder_field_matches_magpylib(J, dims):
    rng = np.random.default_rng(1)
    m = mg.Cylinder(*dims, polarization=J)
    ref = magpy.magnet.Cylinder(polarization=J, dimension=dims)
    pts = _points_away_from_edges(m, 1500, rng, scale=0.02)
    # include points on and near the axis, where the closed forms switch branches
    axis = np.stack([np.full(20, 1e-5), np.zeros(20), np.linspace(-0.03, 0.03, 20)], axis=1)
    pts = np.concatenate([pts, axis[np.abs(np.abs(axis[:, 2]) - dims[1] / 2) > 1e-4]])
    B = mg.field(m, (np.zeros(3), I3), pts)
    Bref = ref.getB(pts)
    err = np.linalg.norm(B - Bref, axis=1) / np.linalg.norm(Bref, axis=1)
    assert err.max() < 1e-4, (err.max(), pts[np.argmax(err)])


def test_far_field_is_the_dipole_field():
    # 1 m away (100 sizes) the float64 closed forms must still resolve the 1e-7 T field
    m = mg.Cuboid((0.01, 0.01, 0.04), moment=(0.5, 0.0, 3.6))
    pts = np.array([[0.0, 0.0, 1.0], [0.7, 0.0, 0.7], [0.0, -1.0, 0.2]])
    B = mg.field(m, (np.zeros(3), I3), pts)
    r = np.linalg.norm(pts, axis=1, keepdims=True)
    rh = pts / r
    Bd = 1e-7 * (3 * rh * (rh @ m.moment)[:, None] - m.moment) / r**3
    assert np.allclose(B, Bd, rtol=2e-3)


# ---------------------------------------------------------------------------------------------------------------------
# dipole grids
# ---------------------------------------------------------------------------------------------------------------------


def test_dipole_grid_counts_match_the_paper_layout():
    epm = mg.Cuboid((0.01, 0.01, 0.04), moment=3.6)
    ipm = mg.Cylinder(0.01, 0.001, moment=0.07)
    assert len(mg.dipole_grid(epm)) == 256  # 4 x 4 x 16, as the paper
    assert len(mg.dipole_grid(ipm)) == 12  # one layer, rings of 3 + 9 equal-area cells (paper: ~5 = density x volume)
    assert len(mg.dipole_grid(mg.Cylinder(0.002, 0.001, moment=1.0))) == 1
    assert len(mg.dipole_grid(epm, 1e6)) == 4  # 1/cm³: 1 x 1 x 4


@pytest.mark.parametrize("magnet", [mg.Cuboid((0.01, 0.01, 0.04), moment=(0.2, 0.0, 3.6)),
                                    mg.Cylinder(0.01, 0.001, moment=(0.0, 0.01, 0.07))])
def test_dipoles_field_is_the_sum_of_its_grid(magnet):
    rng = np.random.default_rng(2)
    R = Rotation.from_euler("zyx", [0.4, 0.2, -0.3]).as_matrix()
    t = np.array([0.002, 0.001, -0.003])
    pts = rng.normal(size=(200, 3)) * 0.03
    pts = pts[np.linalg.norm(pts - t, axis=1) > 0.03]
    B = mg.field(magnet, (t, R), pts, model="dipoles")
    grid = mg.dipole_grid(magnet) @ R.T + t
    m = R @ magnet.moment / len(grid)
    r = pts[:, None, :] - grid[None]
    d = np.linalg.norm(r, axis=-1, keepdims=True)
    rh = r / d
    Bref = (1e-7 * (3 * rh * (rh @ m)[..., None] - m) / d**3).sum(axis=1)
    err = np.linalg.norm(B - Bref, axis=1) / np.linalg.norm(Bref, axis=1)
    assert err.max() < 1e-5


@pytest.mark.parametrize("d, h, density", [(0.01, 0.001, 64e6), (0.008, 0.004, 64e6), (0.02, 0.006, 216e6),
                                           (0.01, 0.001, 1728e6)])
def test_cylinder_grid_has_the_disk_traceless_second_moment(d, h, density):
    """Polar disk grid: centred, and Σx²/N = Σy²/N, Σx²/N − Σz²/N = R²/4 − h²/12 (the solid cylinder's)."""
    g = mg.dipole_grid(mg.Cylinder(d, h, moment=1.0), density)
    m2 = g.T @ g / len(g)
    assert np.allclose(g.mean(0), 0, atol=1e-12)
    assert np.allclose(m2 - np.diag(np.diag(m2)), 0, atol=1e-12)
    assert np.isclose(m2[0, 0], m2[1, 1], rtol=1e-9)
    assert np.isclose(m2[0, 0] - m2[2, 2], d * d / 16 - h * h / 12, rtol=1e-9)
