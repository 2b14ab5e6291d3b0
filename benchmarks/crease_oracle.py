"""How much of the crease angles can a keypoint-based model know? Oracle regressions on the labels (issue 24).

Fits ridge regressions from label features to the 105 crease angles on a training set and reports their MAE on a
test set as a fraction of predicting the training mean (the learnability benchmark's baseline): from the exact 3-D
keypoints in the body frame, from the exact 2-D keypoints (intrinsics, translation and scale removed; linear and
quadratic features), from those with Gaussian pixel noise of sigma px (what a keypoint detector of that accuracy
leaves), from the four deformation ratios, from the worm's geometry and crease stiffness (per world), from the
2-D projections of all the mesh's vertices (exact and with the same noise: what a detector of every fold vertex
would give), and from the body-frame normals of the triangles in view (``pose_baseline.faces_seen``; exact and with
angular noise: what reading the panels' orientation from their shading would give). It says where the crease
information lies: if noisy 2-D keypoints cannot reach a ratio, a network must read the folds from shading and
outline, not from the keypoint layout.

    python benchmarks/crease_oracle.py out/pose_bench/train out/pose_bench/test [--noise 0.5 1 2 3]

Needs the label depth (``faces_seen``) and the mesh vertices in both sets (every dataset has them).
"""

from __future__ import annotations

import argparse
import json

import numpy as np
from pose_baseline import faces_seen  # a sibling script: Python puts benchmarks/ first on sys.path

from warpworm.data import dataset
from warpworm.data.export_keypoints import project

KEYS = ("creases/angle", "keypoints/body", "keypoints/pixel", "camera/K", "labels/deformation", "camera/R", "camera/t",
        "worm/vertices", "poses/body", "depth")
GEOMETRY = ("params/worm.a", "params/worm.b", "params/worm.l0", "params/worm.hinge_stiffness")
"""The worm's randomized geometry [m] and crease stiffness [N/rad]: each world's rest folds follow from them (eq. 7)."""


def load(root: str) -> dict[str, np.ndarray]:
    """The arrays in KEYS and GEOMETRY of dataset folder ``root``, every sample in order, as float64."""
    with dataset.open(root) as ds:
        d = {k: ds.read(k).astype(np.float64) for k in KEYS + GEOMETRY + (("camera/dist",) if "camera/dist" in
                                                                              ds.keys() else ())}
        d["mesh_triangles"] = np.asarray(ds.attrs["mesh_triangles"])
    return d


def vertex_pixels(d: dict) -> np.ndarray:
    """(N, V, 2) [px]: the mesh vertices ``worm/vertices`` projected by each sample's camera, lens distortion
    included (the exports' ``export_keypoints.project``), hidden or not."""
    return project(d["worm/vertices"], d["camera/K"], d["camera/R"], d["camera/t"], d.get("camera/dist"))[0]


def normals_in_view(d: dict, seen: np.ndarray, rng=None, noise_deg: float = 0.0) -> np.ndarray:
    """(N, 4T): each mesh triangle's unit normal in the body frame (``poses/body``), with Gaussian angular noise of
    ``noise_deg`` per component, and its in-view flag ``seen`` (N, T) (``faces_seen``); zeros out of view."""
    T = d["mesh_triangles"]
    V = d["worm/vertices"]
    n = np.einsum("nji,ncj->nci", d["poses/body"][:, :3, :3], np.cross(V[:, T[:, 1]] - V[:, T[:, 0]],
                                                                       V[:, T[:, 2]] - V[:, T[:, 0]]))
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    if noise_deg:
        n = n + rng.normal(0.0, np.radians(noise_deg), n.shape)
        n /= np.linalg.norm(n, axis=-1, keepdims=True)
    return np.c_[(n * seen[..., None]).reshape(len(n), -1), seen]


def ridge_ratio(x_tr, y_tr, x_te, y_te, lam: float) -> float:
    """Test MAE of a ridge fit (standardized features, penalty lam * n) over the training-mean baseline's MAE."""
    mu, sd = x_tr.mean(0), x_tr.std(0) + 1e-12
    a = np.c_[(x_tr - mu) / sd, np.ones(len(x_tr))]
    b = np.c_[(x_te - mu) / sd, np.ones(len(x_te))]
    w = np.linalg.solve(a.T @ a + lam * len(a) * np.eye(a.shape[1]), a.T @ y_tr)
    return float(np.abs(b @ w - y_te).mean() / np.abs(y_tr.mean(0) - y_te).mean())


def layout_2d(uv: np.ndarray, K: np.ndarray) -> np.ndarray:
    """Keypoints (N, P, 2) [px] -> normalized image coordinates, centred and scaled to unit RMS radius: (N, 2P)."""
    p = np.stack([(uv[..., 0] - K[:, 0, 2, None]) / K[:, 0, 0, None],
                  (uv[..., 1] - K[:, 1, 2, None]) / K[:, 1, 1, None]], -1)
    p = p - p.mean(1, keepdims=True)
    return (p / np.sqrt((p**2).sum(-1).mean(1))[:, None, None]).reshape(len(p), -1)


def quadratic(x: np.ndarray) -> np.ndarray:
    i, j = np.triu_indices(x.shape[1])
    return np.c_[x, x[:, i] * x[:, j]]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("train")
    ap.add_argument("test")
    ap.add_argument("--noise", type=float, nargs="*", default=[0.5, 1.0, 2.0, 3.0], help="pixel noise sigmas [px]")
    ap.add_argument("--seed", type=int, default=0)
    a = ap.parse_args(argv)
    tr, te = load(a.train), load(a.test)
    y_tr, y_te = tr["creases/angle"], te["creases/angle"]
    rows = {"3-D keypoints (body frame), linear": ridge_ratio(tr["keypoints/body"].reshape(len(y_tr), -1), y_tr,
                                                               te["keypoints/body"].reshape(len(y_te), -1), y_te, 1e-3),
            "deformation ratios, linear": ridge_ratio(tr["labels/deformation"], y_tr, te["labels/deformation"], y_te,
                                                      1e-3)}
    g_tr, g_te = np.stack([tr[k] for k in GEOMETRY], 1), np.stack([te[k] for k in GEOMETRY], 1)
    rows["geometry a, b, l0 and k_alpha, linear"] = ridge_ratio(g_tr, y_tr, g_te, y_te, 1e-3)
    x_tr, x_te = layout_2d(tr["keypoints/pixel"], tr["camera/K"]), layout_2d(te["keypoints/pixel"], te["camera/K"])
    rows["2-D keypoints exact, linear"] = ridge_ratio(x_tr, y_tr, x_te, y_te, 1e-3)
    rows["2-D keypoints exact, quadratic"] = ridge_ratio(quadratic(x_tr), y_tr, quadratic(x_te), y_te, 1e-2)
    rng = np.random.default_rng(a.seed)
    for sigma in a.noise:  # trained and tested on keypoints with the same detector noise
        n_tr = layout_2d(tr["keypoints/pixel"] + rng.normal(0, sigma, tr["keypoints/pixel"].shape), tr["camera/K"])
        n_te = layout_2d(te["keypoints/pixel"] + rng.normal(0, sigma, te["keypoints/pixel"].shape), te["camera/K"])
        rows[f"2-D keypoints + {sigma:g} px noise, linear"] = ridge_ratio(n_tr, y_tr, n_te, y_te, 1e-2)
        rows[f"2-D keypoints + {sigma:g} px noise, quadratic"] = ridge_ratio(quadratic(n_tr), y_tr, quadratic(n_te),
                                                                            y_te, 1e-1)
    v_tr, v_te = vertex_pixels(tr), vertex_pixels(te)
    for sigma in [0.0] + list(a.noise):
        n_tr = layout_2d(v_tr + rng.normal(0, sigma, v_tr.shape), tr["camera/K"])
        n_te = layout_2d(v_te + rng.normal(0, sigma, v_te.shape), te["camera/K"])
        rows[f"2-D mesh vertices ({v_tr.shape[1]}) + {sigma:g} px noise, quadratic"] = ridge_ratio(
            quadratic(n_tr), y_tr, quadratic(n_te), y_te, 1e-2)
    s_tr, s_te = faces_seen(tr, tr["mesh_triangles"]), faces_seen(te, te["mesh_triangles"])
    for deg in (0.0, 2.0, 5.0):
        rows[f"normals of the triangles in view (body frame) + {deg:g} deg noise, linear"] = ridge_ratio(
            normals_in_view(tr, s_tr, rng, deg), y_tr, normals_in_view(te, s_te, rng, deg), y_te, 1e-3)
    print(f"crease MAE of the training mean on the test set: "
          f"{np.degrees(np.abs(y_tr.mean(0) - y_te).mean()):.2f} deg ({len(y_tr)} train, {len(y_te)} test)")
    print("| oracle (ridge regression) | crease MAE / mean baseline |\n|---|---|")
    for k, v in rows.items():
        print(f"| {k} | {v:.3f} |")
    print(json.dumps(rows))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
