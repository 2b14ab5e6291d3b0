"""Counter-based randomization: a sample's values depend only on (seed, index, attempt), never on batching."""

import math

import numpy as np
import pytest

from warpworm import randomize as rnd


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
    u = rnd.uniform01(rnd.sample_keys(1, np.arange(n)), "s")
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
    assert np.abs(rnd.norm_ppf(np.array([0.001, 0.5, 0.975])) - [-3.090232306, 0.0, 1.959963985]).max() < 1e-8


@pytest.mark.parametrize("spec", [{"uniform": [1, 0]}, {"loguniform": [0, 1]}, {"normal": {"mean": 0, "std": -1}},
                                  {"choice": []}, {"choice": [1, 2], "weights": [1]}, {"uniform": [0, 1], "x": 1},
                                  [1, 2], {"uniform": ["a", 1]}])
def test_bad_specs(spec):
    with pytest.raises(rnd.DistributionError):
        rnd.parse_distribution(spec)
