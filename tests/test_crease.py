"""The worm's crease pattern against independent computations (geometry by hand, not the module's helpers)."""

import numpy as np
import pytest
import trimesh

from warpworm.physics import crease as cr

A, B, N, L0 = 0.020, 0.008, 6, 0.080  # WormParams defaults


@pytest.fixture(scope="module")
def worm():
    return cr.build_worm(A, B, N, l0=L0)


def _alpha_by_cosine_rule(l0, b, n):
    # Independent of eq. (7)'s arccos form: the unit is the base of an isosceles triangle with legs b and apex angle
    # π − α, so (l0/n)/2 = b sin((π − α)/2) = b cos(α/2).
    return 2.0 * np.arccos(l0 / n / (2.0 * b))


def _fold_angle_by_projection(x, i, j, k, l, outward_normal_of_ijk):
    """Fold angle of the crease j–k from the interior angle between the wings projected on the crease's normal plane;
    sign: valley (+) when wing l lies on the outward side of facet (i, j, k)."""
    e = (x[k] - x[j]) / np.linalg.norm(x[k] - x[j])
    wi = (x[i] - x[j]) - np.dot(x[i] - x[j], e) * e
    wl = (x[l] - x[j]) - np.dot(x[l] - x[j], e) * e
    interior = np.arccos(np.clip(np.dot(wi, wl) / np.linalg.norm(wi) / np.linalg.norm(wl), -1, 1))
    mag = np.pi - interior
    side = np.dot(outward_normal_of_ijk, x[l] - x[j])
    return mag if side > 1e-15 else (-mag if side < -1e-15 else 0.0)


def test_rest_alpha_eq7_round_trip_and_limits():
    for l0, b, n in [(0.08, 0.008, 6), (0.05, 0.01, 3), (0.1, 0.006, 10)]:
        alpha = cr.rest_alpha(l0, b, n)
        assert alpha == pytest.approx(_alpha_by_cosine_rule(l0, b, n), abs=1e-12)
        assert n * cr.unit_length(b, alpha) == pytest.approx(l0, rel=1e-12)
    assert cr.rest_alpha(6 * 2 * 0.008, 0.008, 6) == pytest.approx(0.0, abs=1e-7)  # flat sheet: l0/n = 2b
    assert cr.unit_length(0.008, 0.0) == pytest.approx(0.016)
    arr = cr.rest_alpha(np.array([0.06, 0.08]), np.array([0.008, 0.009]), 6)
    assert arr.shape == (2,)
    with pytest.raises(ValueError, match="exceeds 2b"):
        cr.rest_alpha(0.2, 0.008, 6)
    with pytest.raises(ValueError):
        cr.rest_alpha(0.0, 0.008, 6)
    with pytest.raises(ValueError):
        cr.build_worm(A, B, N)
    with pytest.raises(ValueError):
        cr.build_worm(A, B, N, l0=L0, alpha=1.0)
    with pytest.raises(ValueError, match="inradius"):
        cr.build_worm(A, 0.02, N, alpha=2.5)  # faces would pinch through the axis


def test_sizes_and_label_counts(worm):
    assert worm.num_vertices == 3 * (2 * N + 1)
    assert worm.num_triangles == 12 * N
    assert worm.num_edges == 3 * (2 * N + 1) + 12 * N
    assert worm.num_hinges == worm.num_edges - 6
    counts = np.bincount(worm.hinge_label, minlength=3)
    assert counts[cr.VALLEY] == 3 * N  # unit middles
    assert counts[cr.MOUNTAIN] == 3 * (N - 1) + 6 * N  # interior unit boundaries + prism corners
    assert counts[cr.FLAT] == 6 * N  # trapezoid diagonals
    assert np.sum(worm.edge_label == cr.BOUNDARY) == 6
    assert np.array_equal(worm.hinge_label, worm.edge_label[worm.hinge_edge])
    assert worm.vertices.dtype == np.float64 and worm.triangles.dtype == np.int32 and worm.hinges.dtype == np.int32


def _classify_edges(p):
    x = p.vertices
    d = x[p.edges[:, 1]] - x[p.edges[:, 0]]
    transverse = np.abs(d[:, 0]) < 1e-12
    x_mid = 0.5 * (x[p.edges[:, 0], 0] + x[p.edges[:, 1], 0])
    return transverse, x_mid


@pytest.mark.parametrize("n, l0", [(N, L0), (4, 0.05), (5, 0.075)])
def test_every_hinge_dihedral_equals_its_rest_angle(n, l0):
    p = cr.build_worm(A, B, n, l0=l0)
    alpha = _alpha_by_cosine_rule(l0, B, n)
    x = p.vertices
    # Independent expected corner angle: faces tilted by ±α/2 about their transverse direction have unit normals
    # cos(α/2) n0 ± sin(α/2) x̂ (same sign for neighbours in a half unit); prism corner: n0·n0' = cos 120°.
    corner = -np.arccos(np.cos(alpha / 2) ** 2 * np.cos(2 * np.pi / 3) + np.sin(alpha / 2) ** 2)
    transverse, _ = _classify_edges(p)
    tri_of = {}
    for t in p.triangles:  # which oriented facet holds the directed edge (j, k)
        for c in range(3):
            tri_of[(t[c], t[(c + 1) % 3])] = t
    for h, (i, j, k, l) in enumerate(p.hinges):
        t1 = tri_of[(j, k)]
        assert i in t1 and tri_of[(k, j)].tolist().count(l) == 1
        nrm = np.cross(x[t1[1]] - x[t1[0]], x[t1[2]] - x[t1[0]])
        measured = _fold_angle_by_projection(x, i, j, k, l, nrm)
        lab = p.hinge_label[h]
        e = p.hinge_edge[h]
        if lab == cr.FLAT:
            expected = 0.0
        elif transverse[e]:
            expected = alpha if lab == cr.VALLEY else -alpha
        else:
            assert lab == cr.MOUNTAIN
            expected = corner
        assert measured == pytest.approx(expected, abs=1e-9), (h, lab)
        assert p.hinge_rest_angle[h] == pytest.approx(expected, abs=1e-9)
    # The module's own signed dihedral agrees with the independent one.
    assert np.allclose(cr.dihedral_angles(x, p.hinges), p.hinge_rest_angle, atol=1e-12)


def test_unit_length_and_floor(worm):
    x = worm.vertices
    xs = np.unique(np.round(x[:, 0], 12))
    assert len(xs) == 2 * N + 1
    assert np.allclose(np.diff(xs[::2]), L0 / N, rtol=1e-12)
    assert xs[0] == pytest.approx(0.0, abs=1e-15) and xs[-1] == pytest.approx(L0, rel=1e-12)
    full = np.isin(np.round(x[:, 0], 12), xs[::2])
    assert np.all(x[:, 2] >= -1e-15)
    assert np.sum(np.abs(x[:, 2]) < 1e-15) == 2 * (N + 1)  # bottom corners of every unit boundary
    assert np.all(x[~full, 2] > 1e-4)  # unit middles are lifted (pinched in)


def test_every_bar_has_its_design_length(worm):
    alpha = _alpha_by_cosine_rule(L0, B, N)
    # Trapezoid face of a half unit: parallel sides a (boundary) and a' (middle), slant width b. Moving each side of
    # an equilateral triangle in by d shrinks its side by 2√3 d; the face is tilted by α/2 so d = b sin(α/2).
    a_in = A - 2 * np.sqrt(3) * B * np.sin(alpha / 2)
    leg = np.hypot(B, (A - a_in) / 2)
    diag = np.hypot(B, (A + a_in) / 2)
    x = worm.vertices
    L = np.linalg.norm(x[worm.edges[:, 1]] - x[worm.edges[:, 0]], axis=1)
    assert np.allclose(L, worm.edge_rest_length, rtol=1e-13)
    transverse, x_mid = _classify_edges(worm)
    boundary_section = np.isclose(np.mod(x_mid / (L0 / N) + 1e-9, 1.0), 0.0, atol=1e-6)
    expected = np.where(transverse, np.where(boundary_section, A, a_in), np.nan)
    long_ = ~transverse
    is_diag = worm.edge_label == cr.FLAT
    expected[long_ & is_diag] = diag
    expected[long_ & ~is_diag] = leg
    assert np.allclose(L, expected, rtol=1e-12)
    # slant width of every face panel is b: distance between its two parallel (transverse) sides
    h_idx = np.nonzero(transverse[worm.hinge_edge])[0]
    i, j, k, l = worm.hinges[h_idx].T
    for w in (i, l):
        e = x[k] - x[j]
        dist = np.linalg.norm(np.cross(x[w] - x[j], e), axis=1) / np.linalg.norm(e, axis=1)
        assert np.allclose(dist, B, rtol=1e-12)
    assert np.allclose(worm.hinge_length, L[worm.hinge_edge])


def test_surface_is_oriented_tube_closed_around_circumference(worm):
    tri = worm.triangles
    directed = {}
    for t in tri:
        for c in range(3):
            key = (int(t[c]), int(t[(c + 1) % 3]))
            assert key not in directed, "two facets traverse an edge the same way"
            directed[key] = 1
    undirected = {}
    for u, v in directed:
        undirected.setdefault((min(u, v), max(u, v)), []).append((u, v))
    x = worm.vertices
    bnd = [e for e, hs in undirected.items() if len(hs) == 1]
    assert all(len(hs) <= 2 for hs in undirected.values())
    assert len(bnd) == 6
    # boundary only at the two open ends
    ends = sorted({round(float(x[u, 0]), 12) for e in bnd for u in e})
    assert ends == [0.0, round(L0, 12)]
    assert {tuple(e) for e in worm.edges[worm.edge_label == cr.BOUNDARY]} == set(bnd)
    # outward normals: signed volume with end caps equals the frustum volumes (positive)
    tail = np.nonzero(np.abs(x[:, 0]) < 1e-12)[0]
    head = np.nonzero(np.abs(x[:, 0] - L0) < 1e-12)[0]

    def cap(idx, outward):
        c = x[idx].mean(0)
        ang = np.arctan2(x[idx, 2] - c[2], x[idx, 1] - c[1])
        o = idx[np.argsort(ang)]  # CCW about +x
        return o if outward > 0 else o[::-1]

    closed = np.vstack([tri, cap(tail, -1)[None], cap(head, +1)[None]])
    vol = np.sum(np.einsum("ij,ij->i", x[closed[:, 0]], np.cross(x[closed[:, 1]], x[closed[:, 2]]))) / 6
    alpha = _alpha_by_cosine_rule(L0, B, N)
    a_in = A - 2 * np.sqrt(3) * B * np.sin(alpha / 2)
    area, area_in = np.sqrt(3) / 4 * A**2, np.sqrt(3) / 4 * a_in**2
    h = L0 / N / 2
    frustum = h / 3 * (area + area_in + np.sqrt(area * area_in))
    assert vol == pytest.approx(2 * N * frustum, rel=1e-12)
    m = trimesh.Trimesh(x, closed, process=False)
    assert m.is_watertight and m.is_winding_consistent and m.volume > 0


def test_keypoints_segments_and_mounts(worm):
    r = A / (2 * np.sqrt(3))
    kp = worm.keypoints()
    assert worm.keypoint_names == ["seg0", "seg1", "seg2", "seg3", "seg4", "tail", "head"]
    expect_x = np.r_[(np.arange(5) + 0.5) * L0 / 5, 0.0, L0]
    assert np.allclose(kp[:, 0], expect_x, atol=1e-15)
    assert np.allclose(kp[:, 1], 0.0, atol=1e-15) and np.allclose(kp[:, 2], r, atol=1e-15)
    assert np.allclose(worm.keypoint_weights.sum(1), 1.0)
    cx = worm.vertices[worm.triangles].mean(1)[:, 0]
    assert np.array_equal(worm.triangle_segment, np.clip(np.floor(cx / (L0 / 5)), 0, 4).astype(int))
    assert set(np.unique(worm.triangle_segment)) == set(range(5))
    pos, rot = cr.mount_poses(worm)
    assert np.allclose(pos, [[0, 0, r], [L0 / 2, 0, r], [L0, 0, r]], atol=1e-15)
    assert np.allclose(rot @ rot.transpose(0, 2, 1), np.eye(3)) and np.allclose(np.linalg.det(rot), 1)
    assert np.allclose(rot[:, :, 2], [[-1, 0, 0], [1, 0, 0], [-1, 0, 0]])  # moment = own +z: tail −x, centre +x, head −x
    # The mount frame follows a rigid motion of the worm.
    Q = trimesh.transformations.rotation_matrix(0.7, [0.3, -0.5, 0.8])[:3, :3]
    t = np.array([0.1, -0.2, 0.05])
    pos2, rot2 = cr.mount_poses(worm, worm.vertices @ Q.T + t)
    assert np.allclose(pos2, pos @ Q.T + t) and np.allclose(rot2, Q @ rot)
    o, R = cr.frame_from_vertices(worm.vertices[worm.mount_vertices])
    assert np.allclose(R[:, :, 0], [1, 0, 0])  # section normal points forward
    # Odd n: the centre mount sits on the unit boundary just tail-side of the middle.
    p5 = cr.build_worm(A, B, 5, l0=0.075)
    assert cr.mount_poses(p5)[0][1, 0] == pytest.approx(2 * 0.075 / 5)


def test_batched_vertices_match_single_builds():
    a = np.array([0.02, 0.018, 0.022])
    b = np.array([0.008, 0.007, 0.009])
    l0 = np.array([0.08, 0.07, 0.09])
    alpha = cr.rest_alpha(l0, b, N)
    xs, lengths, angles = cr.worm_rest_state(a, b, alpha, N)
    assert xs.shape == (3, 3 * (2 * N + 1), 3)
    for w in range(3):
        p = cr.build_worm(a[w], b[w], N, l0=l0[w])
        assert np.allclose(xs[w], p.vertices, atol=1e-15)
        assert np.allclose(lengths[w], p.edge_rest_length) and np.allclose(angles[w], p.hinge_rest_angle)
        ref = cr.build_worm(A, B, N, l0=L0)
        assert np.array_equal(ref.hinges, p.hinges) and np.array_equal(ref.edges, p.edges)
        assert np.array_equal(ref.keypoint_vertices, p.keypoint_vertices)
        assert np.allclose(ref.keypoint_weights, p.keypoint_weights)


def test_dihedral_gradient_matches_finite_differences(worm):
    rng = np.random.default_rng(0)
    x = worm.vertices + 1e-3 * rng.normal(size=worm.vertices.shape)
    g = cr.dihedral_gradients(x, worm.hinges)
    eps = 1e-7
    for h in rng.choice(worm.num_hinges, 12, replace=False):
        for c in range(4):
            for d in range(3):
                xp, xm = x.copy(), x.copy()
                xp[worm.hinges[h, c], d] += eps
                xm[worm.hinges[h, c], d] -= eps
                fd = (cr.dihedral_angles(xp, worm.hinges[h:h + 1]) - cr.dihedral_angles(xm, worm.hinges[h:h + 1]))
                assert g[h, c, d] == pytest.approx(fd[0] / (2 * eps), rel=1e-5, abs=1e-4)


def test_from_trimesh_round_trip(worm):
    mesh = worm.to_trimesh()
    for labels in (worm.label_dict(), worm.edge_label, None):
        p = cr.CreasePattern.from_trimesh(mesh, labels)
        assert np.array_equal(p.edges, worm.edges)
        assert np.array_equal(p.edge_label, worm.edge_label)
        assert np.array_equal(p.hinges, worm.hinges)
        assert np.array_equal(p.hinge_label, worm.hinge_label)
        assert np.allclose(p.hinge_rest_angle, worm.hinge_rest_angle, atol=1e-12)
        assert np.allclose(p.hinge_length, worm.hinge_length)
        assert np.array_equal(p.triangle_segment, worm.triangle_segment)
        assert np.allclose(p.keypoints()[:5], worm.keypoints()[:5], atol=2e-3)  # vertex-bin means, not section blends
    bad = mesh.copy()
    bad.faces = bad.faces.copy()
    bad.faces[0] = bad.faces[0][::-1]
    with pytest.raises(ValueError, match="oriented"):
        cr.CreasePattern.from_trimesh(bad)


def test_export_glb_and_ply_reload(worm, tmp_path):
    glb = cr.export_mesh(worm, tmp_path / "worm.glb")
    scene = trimesh.load(glb)
    assert {"surface", "valley", "mountain"} <= set(scene.geometry)
    p = cr.load_pattern(glb, worm.label_dict())
    assert np.allclose(p.vertices, worm.vertices, atol=1e-7)  # GLB stores float32
    assert np.array_equal(p.hinges, worm.hinges)
    assert np.allclose(p.hinge_rest_angle, worm.hinge_rest_angle, atol=1e-4)
    red = scene.geometry["valley"].visual.face_colors[:, :3]
    assert np.all(red[:, 0] > 200) and np.all(red[:, 2] < 100)
    ply = cr.export_mesh(worm, tmp_path / "worm.ply")
    m = trimesh.load(ply, process=False)
    assert len(m.vertices) > worm.num_vertices and np.allclose(m.vertices[: worm.num_vertices], worm.vertices)
    fc = m.visual.face_colors[:, :3]
    assert np.any((fc[:, 0] > 200) & (fc[:, 2] < 100)) and np.any((fc[:, 2] > 200) & (fc[:, 0] < 100))
    bare = cr.export_mesh(worm, tmp_path / "bare.ply", creases=False)
    p2 = cr.load_pattern(bare)
    assert np.array_equal(p2.hinges, worm.hinges) and np.array_equal(p2.edge_label, worm.edge_label)


def test_axial_compression_needs_only_the_valley_bars_to_stretch(worm):
    # Independent rigidity matrix: one row per bar, d(length)/d(positions).
    x, E = worm.vertices, worm.edges
    d = (x[E[:, 1]] - x[E[:, 0]]) / worm.edge_rest_length[:, None]
    C = np.zeros((len(E), worm.num_vertices, 3))
    np.add.at(C, (np.arange(len(E)), E[:, 1]), d)
    np.add.at(C, (np.arange(len(E)), E[:, 0]), -d)
    C = C.reshape(len(E), -1)
    assert np.allclose(C, cr.rigidity_matrix(x, E))
    # All bars kept: isostatic (only the 6 rigid motions), so shortening the worm must strain bars.
    assert np.linalg.matrix_rank(C) == 3 * worm.num_vertices - 6
    _, strain, energy = cr.compression_mode(worm)
    assert energy > 1.0
    # Without the valley (unit-middle ring) bars: a mechanism; every other bar keeps its length to first order.
    valley = worm.edge_label == cr.VALLEY
    assert np.linalg.matrix_rank(C[~valley]) == 3 * worm.num_vertices - 6 - valley.sum()
    u, strain, energy = cr.compression_mode(worm, released=valley)
    assert energy < 1e-18 and np.abs(strain[~valley]).max() < 1e-9
    kp = worm.keypoints(worm.vertices + 1e-6 * u)
    assert kp[6, 0] - kp[5, 0] == pytest.approx(L0 - 1e-6, abs=1e-12)  # it does shorten the worm
