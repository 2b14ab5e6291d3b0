"""Counter-based randomization: a sample's values depend only on (seed, index, attempt), never on batching."""

import math
from pathlib import Path

import numpy as np
import pytest

from warpworm import rng
from warpworm.data import randomize as rnd


def test_draws_do_not_depend_on_batching():
    dists = {"a": rnd.Uniform(0, 1), "b": rnd.TruncNormal(0.27, 0.02, 0.2, 0.34), "c": rnd.Choice(("x", "y", "z"))}
    idx = np.arange(1000)
    full = rnd.draw(dists, 5, idx)
    parts = [rnd.draw(dists, 5, idx[i:i + 37]) for i in range(0, 1000, 37)]
    single = rnd.draw(dists, 5, np.array([733]))
    for k in dists:
        assert np.array_equal(full[k], np.concatenate([p[k] for p in parts]))
        assert single[k][0] == full[k][733]
    other_attempt = rnd.draw(dists, 5, idx, attempt=1)
    assert not np.array_equal(other_attempt["a"], full["a"])
    # adding a parameter does not shift the others (streams are keyed by name)
    more = rnd.draw({**dists, "new": rnd.Uniform(0, 1)}, 5, idx)
    assert np.array_equal(more["a"], full["a"])


def test_distributions_have_the_right_law():
    n = 200_000
    u = rng.uniform01(rng.sample_keys(1, np.arange(n)), "s")
    assert 0 <= u.min() and u.max() < 1 and abs(u.mean() - 0.5) < 0.005
    idx = np.arange(n)
    x = rnd.LogUniform(0.01, 1.0).sample(u, idx)
    assert abs(np.mean(np.log10(x)) + 1.0) < 0.01 and x.min() >= 0.01 and x.max() <= 1.0
    t = rnd.TruncNormal(0.0, 1.0, -1.0, 2.0).sample(u, idx)
    assert t.min() >= -1 and t.max() <= 2
    # mean of N(0,1) truncated to [-1, 2]: (phi(-1) - phi(2)) / (Phi(2) - Phi(-1))
    phi = lambda z: math.exp(-z * z / 2) / math.sqrt(2 * math.pi)  # noqa: E731
    Phi = lambda z: 0.5 * (1 + math.erf(z / math.sqrt(2)))  # noqa: E731
    assert abs(t.mean() - (phi(-1) - phi(2)) / (Phi(2) - Phi(-1))) < 0.01
    c = rnd.Choice((1.0, 2.0, 3.0), (1.0, 0.0, 3.0)).sample(u, idx)
    assert set(np.unique(c)) == {1.0, 3.0} and abs(np.mean(c == 3.0) - 0.75) < 0.01
    g = rnd.Grid(("p", "q")).sample(u, idx)
    assert list(g[:4]) == ["p", "q", "p", "q"]
    assert np.abs(rng.norm_ppf(np.array([0.001, 0.5, 0.975])) - [-3.090232306, 0.0, 1.959963985]).max() < 1e-8


@pytest.mark.parametrize("spec", [{"uniform": [1, 0]}, {"loguniform": [0, 1]}, {"normal": {"mean": 0, "std": -1}},
                                  {"choice": []}, {"choice": [1, 2], "weights": [1]}, {"uniform": [0, 1], "x": 1},
                                  [1, 2], {"uniform": ["a", 1]}])
def test_bad_specs(spec):
    with pytest.raises(rnd.DistributionError):
        rnd.parse_distribution(spec)


def test_seed_uniforms_are_the_counter_generator_keyed_by_seed():
    # an independent re-implementation of the seed-keyed chain (SplitMix64 finalizer, module docstring)
    M = (1 << 64) - 1

    def mix(x):
        x = ((x ^ (x >> 30)) * 0xBF58476D1CE4E5B9) & M
        x = ((x ^ (x >> 27)) * 0x94D049BB133111EB) & M
        return x ^ (x >> 31)

    seeds, stream = [0, 7, 2**40 + 3], 0xCA3E0 + 2
    got = rng.seed_uniforms(seeds, stream, 5)
    for i, s in enumerate(seeds):
        x = mix((s * 0x9E3779B97F4A7C15 + stream * 0xD1B54A32D192ED03) & M)
        want = [(mix(x ^ (((j + 1) * 0x9E3779B97F4A7C15) & M)) >> 11) / 2.0**53 for j in range(5)]
        assert got[i].tolist() == want
    # batch-independent
    assert np.array_equal(rng.seed_uniforms(seeds[1:2], stream, 5)[0], got[1])


def test_randomized_params_are_the_dataset_jobs_draws():
    from warpworm.data.config import ConfigError, load_config
    from warpworm.data.sampling import draw_worm, randomized_params

    cfg = load_config("default")
    p = randomized_params("default", 5, seed=11)
    # world w is trajectory w at attempt 0 of the same config with master seed 11
    d = draw_worm(load_config("default", seed=11), np.arange(5), np.zeros(5, np.int64))
    assert np.array_equal(p.hinge_stiffness, d["worm.hinge_stiffness"])
    assert np.array_equal(p.mu_kinetic, np.minimum(d["worm.mu_kinetic"], d["worm.mu_static"]))
    assert np.array_equal(p.ipm_moment[:, 1], d["worm.ipm_moment_centre"])
    assert p.ipm_moment.shape == (5, 3) and p.epm_size.shape == (5, 3)
    assert not np.isnan(p.orientation).any()  # the gait preset filled in
    # gait and direction per world where they differ (the default config draws both)
    assert np.array_equal(np.broadcast_to(p.gait, (5,)), np.asarray(d["worm.gait"]).astype(str))
    assert np.array_equal(np.broadcast_to(p.backward, (5,)), np.asarray(d["worm.backward"]).astype(bool))
    assert not np.array_equal(randomized_params(cfg, 5, seed=12).hinge_stiffness, p.hinge_stiffness)
    one = randomized_params(load_config("default", ["randomize.worm.gait=inchworm"]), 3, seed=0)
    assert one.gait == "inchworm"
    # the magnet model is one per solver batch: drawn with two values, refused, naming it
    two = load_config("default", ["randomize.worm.magnet_model={choice: [analytic, dipoles]}"])
    with pytest.raises(ConfigError, match="randomize.worm.magnet_model"):
        randomized_params(two, 64, seed=0)
    with pytest.raises(ConfigError, match="num_worlds"):
        randomized_params(cfg, 0, seed=0)


def test_different_seeds_draw_different_samples():
    """Seeds are independent streams: no (seed, index) key repeats across seeds 0..7 and 4,096 indices (the seed
    used to join the index unmixed, so seed s + 1 at index i − 1 gave seed s's sample i), and seed 1's draws are
    not seed 0's shifted by one index."""
    idx = np.arange(4096)
    keys = np.concatenate([rng.sample_keys(s, idx) for s in range(8)])
    assert len(np.unique(keys)) == keys.size
    u0 = rng.uniform01(rng.sample_keys(0, idx), "worm.hinge_stiffness")
    u1 = rng.uniform01(rng.sample_keys(1, idx), "worm.hinge_stiffness")
    assert not np.any(np.isclose(u0[1:], u1[:-1]))


@pytest.mark.parametrize("name", sorted(p.stem for p in
                                        (Path(__file__).resolve().parents[1] / "dataset_configs").glob("*.yaml")))
def test_packaged_configs_keep_the_epm_beneath_the_plate(name):
    """Every draw of every packaged config puts the EPM's closest approach h (the gait preset's, times its scale)
    at or below the plate's underside (h >= support_thickness): a draw that did not would stop the job."""
    from warpworm.data.config import load_config
    from warpworm.data.sampling import randomized_params

    W = 4096
    # one magnet model per solver batch (production draws it per batch): fixed here, it does not move h
    p = randomized_params(load_config(name, ["randomize.worm.magnet_model=analytic"]), W, seed=5)
    h = np.broadcast_to(p.closest_approach, (W,)) * np.broadcast_to(p.closest_approach_scale, (W,))
    plate = np.broadcast_to(p.support_thickness, (W,))
    assert (h >= plate).all(), (name, float(h.min()), float(plate.max()))
