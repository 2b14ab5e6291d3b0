"""Every packaged config does what its header says (issue 25: sweep_kalpha swept k_alpha about 0.3 while the
material is 0.005, so its worms never folded).

Each config runs for a few trajectories (its own physics, cameras and frame times; small images, few worlds) and is
checked with the measures ``warpworm report`` prints (warpworm.data.report: the crease-angle range within a
trajectory, the smallest segment ratio of a trajectory) and with the parameters written per sample:

==========================  ===========================================================================================
default                     the worm deforms: median crease range >= 20 deg, some trajectory at a ratio <= 0.9
gait_<g>                    only gait <g>, forward and backward alternating; it deforms (>= 20 deg in every trajectory)
gait_peristaltic_skin       peristaltic forward on a one-way skin of 1.5-3x; every trajectory squeezes to <= 0.9
sweep_kalpha                k_alpha takes exactly its 5 grid values about the material's 0.005 N/rad, trajectory t has
                            value t % 5; it deforms (median >= 20 deg, >= 30 % of trajectories <= 0.9); softer folds
                            more (the softest's range above the stiffest's)
sweep_mu                    mu_static takes its 4 grid values, mu_kinetic <= mu_static, the floor inclined 0.05 rad
production                  its ranges drawn (a, b, l0, k_alpha inside the config's), both magnet models, a camera per
                            frame, 256 x 256 images
deform_views                frames by the gait's phase and close cameras: it deforms (median >= 20 deg)
==========================  ===========================================================================================

A config added to dataset_configs/ without a row here fails :func:`test_every_packaged_config_has_a_promise`.
"""

from __future__ import annotations

import numpy as np
import pytest

from warpworm.data import dataset as ds
from warpworm.data.config import load_config, config_packaged_names
from warpworm.data.job import generate
from warpworm.data.report import folder_summary, load_folder, per_trajectory_min, within_trajectory_range

TRAJECTORIES = 6


def _run(name, tmp_path, trajectories=TRAJECTORIES, size=(32, 24), extra=()):
    F = load_config(name).frames_per_trajectory
    n = trajectories * F
    cfg = load_config(name, [f"sim.worlds={trajectories}", f"render.width={size[0]}", f"render.height={size[1]}",
                             "output.preview=false", "sim.device=cpu", f"shard_size={n}", *extra], num_samples=n)
    out = tmp_path / name
    generate(cfg, out, progress=False, log=lambda m: None)
    d = load_folder(out)
    return d, folder_summary(d), ds.open(out)


def _per_traj(reader, key):
    traj = reader.read("trajectory")
    ids, inv = np.unique(traj, return_index=True)
    return reader.read(key)[inv]


def _deforms(summary, median_deg=20.0, frac=None):
    r = summary["crease_range_within_trajectory_deg"]
    assert r["median"] >= median_deg, summary
    if frac is not None:
        assert summary["fraction_trajectories_min_deformation_le_0.9"] >= frac, summary


def check_default(tmp_path):
    _, s, _ = _run("default", tmp_path)
    _deforms(s, 20.0, frac=1 / TRAJECTORIES)


def _check_gait(gait, tmp_path):
    d, s, r = _run(f"gait_{gait}", tmp_path)
    assert set(r.read("params/worm.gait").astype(str)) == {gait}
    back = _per_traj(r, "params/worm.backward").astype(bool)
    assert back.tolist() == [bool(t % 2) for t in range(TRAJECTORIES)]  # grid [false, true]
    assert d.values["crease_range_within_trajectory_deg"].min() >= 20.0, s


def check_gait_peristaltic(tmp_path):
    _check_gait("peristaltic", tmp_path)


def check_gait_omega(tmp_path):
    _check_gait("omega", tmp_path)


def check_gait_inchworm(tmp_path):
    _check_gait("inchworm", tmp_path)


def check_gait_peristaltic_skin(tmp_path):
    d, s, r = _run("gait_peristaltic_skin", tmp_path)
    assert set(r.read("params/worm.gait").astype(str)) == {"peristaltic"}
    assert not r.read("params/worm.backward").astype(bool).any()
    ratio = r.read("params/worm.friction_backward_ratio")
    assert ratio.min() >= 1.5 and ratio.max() <= 3.0
    assert d.values["min_deformation_per_trajectory"].max() <= 0.9, s  # every trajectory squeezes


def check_sweep_kalpha(tmp_path):
    d, s, r = _run("sweep_kalpha", tmp_path, trajectories=10)
    grid = [0.0025, 0.0035, 0.005, 0.007, 0.01]
    k = _per_traj(r, "params/worm.hinge_stiffness")
    assert np.allclose(k, [grid[t % 5] for t in range(10)])
    assert min(grid) < 0.005 < max(grid)  # about the default material's k_alpha
    from warpworm.physics.params import WormParams

    assert WormParams().hinge_stiffness == 0.005
    _deforms(s, 20.0, frac=0.3)
    ids, rng = within_trajectory_range(r.read("trajectory"), np.degrees(r.read("creases/angle")))
    soft, stiff = rng[np.isclose(k, grid[0])], rng[np.isclose(k, grid[-1])]
    assert soft.mean() > stiff.mean(), (soft, stiff)


def check_sweep_mu(tmp_path):
    _, s, r = _run("sweep_mu", tmp_path, trajectories=4)
    mu = _per_traj(r, "params/worm.mu_static")
    assert np.allclose(mu, [0.15, 0.2, 0.268, 0.35])
    assert np.all(r.read("params/worm.mu_kinetic") <= r.read("params/worm.mu_static") + 1e-12)
    assert np.allclose(r.read("params/worm.floor_incline"), 0.05)


def check_production(tmp_path):
    d, s, r = _run("production", tmp_path, trajectories=8, size=(256, 256))
    cfg = load_config("production")
    for name in ("a", "b", "l0", "hinge_stiffness"):
        lo, hi = cfg.randomize["worm"][name].to_yaml().popitem()[1]
        v = r.read(f"params/worm.{name}")
        assert v.min() >= lo and v.max() <= hi and np.ptp(v) > 0, name
    assert r.read("rgb", [0]).shape[1:3] == (256, 256)
    traj = r.read("trajectory")
    R = r.read("camera/R")
    first = traj == traj[0]
    assert not np.allclose(R[first][0], R[first][1])  # camera_per_frame: a new camera every frame


def check_deform_views(tmp_path):
    _, s, _ = _run("deform_views", tmp_path, trajectories=4, size=(64, 64))
    _deforms(s, 20.0)


PROMISES = {n[len("check_"):]: f for n, f in globals().items() if n.startswith("check_")}


def test_every_packaged_config_has_a_promise():
    missing = sorted(set(config_packaged_names()) - set(PROMISES))
    assert not missing, f"packaged config(s) {missing} have no check of what their header says: add check_<name>"


@pytest.mark.parametrize("name", sorted(PROMISES))
def test_packaged_config_does_what_its_header_says(name, tmp_path):
    if name not in config_packaged_names():
        pytest.skip(f"{name}.yaml is not packaged in this tree")
    PROMISES[name](tmp_path)


def test_the_header_names_its_own_command():
    """Each header shows how to run it (``warpworm generate <name> --out ...``), as the README's table does."""
    from importlib import resources

    for name in config_packaged_names():
        text = (resources.files("warpworm.dataset_configs") / f"{name}.yaml").read_text()
        head = "".join(ln for ln in text.splitlines(keepends=True) if ln.startswith("#"))
        assert f"warpworm generate {name}" in head, name
