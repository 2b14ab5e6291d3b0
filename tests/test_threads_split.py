"""One batch of worlds over the cores as threads of one process (warpworm.analysis.world_split): the shares run at
the same time on their own threads, each with its own Simulator stepping with CPU graphs behind the capture gate,
and every per-world result (displacements, gait metrics, saved frames) equals the one-batch run bit for bit. Tiny
sizes: the speed is measured in benchmarks/bench_threads.py, not here."""

import threading

import numpy as np
import pytest

from warpworm.analysis import world_split as ws
from warpworm.analysis.gait_runs import randomized_params, run_gait_split


def test_shares_are_contiguous_and_bad_counts_are_refused():
    assert ws.world_shares(5, 2) == [(0, 2), (2, 5)]
    assert ws.world_shares(2, 8) == [(0, 1), (1, 2)]  # never more shares than worlds
    assert ws.world_shares(7, 1) == [(0, 7)]
    with pytest.raises(ValueError, match=r"workers: got 0; expected >= 1"):
        ws.world_shares(4, 0)
    with pytest.raises(ValueError, match=r"num_worlds: got 0; expected >= 1"):
        ws.world_shares(0, 2)


def test_shares_run_at_once_on_their_own_threads_with_graphs_behind_the_capture_gate():
    """Each share holds the capture gate shared (warpworm.sim.capture_gate) and steps with CPU graphs: a barrier both
    shares reach inside their Warp work, and again between replays, opens only if they run at once."""
    from warpworm.physics.params import WormParams
    from warpworm.sim import capture_gate
    from warpworm.sim.model import Model
    from warpworm.sim.simulator import Simulator

    barrier = threading.Barrier(2, timeout=60)
    seen = {}

    def share(lo, hi):
        sim = Simulator(Model.from_params(WormParams(), hi - lo, "cpu"), dt=0.004, substeps=2)
        for _ in range(3):
            state = sim.initial_state()  # plain Warp work (arrays from host data): both shares at once
            barrier.wait()
            sim.step(state, 3)  # a plain first step, a capture alone, then replays
            with capture_gate.released():
                barrier.wait()
        seen[(lo, hi)] = (threading.get_ident(), ws.in_split(), sim.use_graph)
        return {"n": np.array([hi - lo])}

    out = ws.concat(ws.run_shares(share, 5, workers=2), {"n": 0})
    assert out["n"].tolist() == [2, 3]
    (t0, s0, g0), (t1, s1, g1) = seen[(0, 2)], seen[(2, 5)]
    assert t0 != t1 and threading.get_ident() not in (t0, t1)
    assert s0 and s1 and g0 and g1  # graphs, not a silent fallback to plain launches
    assert not ws.in_split()  # the flag does not leak into the caller's thread


def test_a_capture_waits_for_the_other_threads_warp_work_and_holds_new_work_off(monkeypatch):
    """The gate's order: thread B's capture starts only once thread A is out of its Warp work (here: into a replay);
    a thread C arriving while the capture is queued, and A back from its replay, wait until it has ended (a queued
    capture goes first); a thread cannot take the gate twice."""
    from warpworm.sim import capture_gate

    log, lock = [], threading.Lock()
    a_in, b_in, a_go, captured = (threading.Event() for _ in range(4))
    # events instead of sleeps: the gate's condition reports who waits on it, and whether a capture runs then
    blocked = {name: threading.Event() for name in "bc"}  # that thread waited at the gate
    c_held_by_capture = threading.Event()  # C waited while B's capture ran

    class Gate(threading.Condition):
        def wait(self, timeout=None):
            name = threading.current_thread().name
            if name in blocked:
                blocked[name].set()
            if name == "c" and capture_gate._state["capturing"]:
                c_held_by_capture.set()
            return super().wait(timeout)

    monkeypatch.setattr(capture_gate, "_cond", Gate())

    def note(x):
        with lock:
            log.append(x)

    def a():
        with capture_gate.hold():
            a_in.set()
            a_go.wait(10)
            note("a work done")
            with capture_gate.released():  # a replay: the capture may run now
                captured.wait(10)
            note("a work again")

    def b():
        a_in.wait(10)
        with capture_gate.hold():
            b_in.set()
            with capture_gate.capturing():
                note("b captures")
                # C, woken by the capture's start (the notify comes with ``capturing`` set), waits again; a gate
                # letting it in would log 'c work' here
                assert c_held_by_capture.wait(10)
                note("b capture done")
                captured.set()

    def c():
        with capture_gate.hold():
            note("c work")

    threads = [threading.Thread(target=f, name=n, daemon=True) for f, n in ((a, "a"), (b, "b"))]
    for t in threads:
        t.start()
    assert b_in.wait(10)
    assert blocked["b"].wait(10) and capture_gate._state["waiting"] == 1  # B's capture queued behind A
    threads.append(threading.Thread(target=c, name="c", daemon=True))
    threads[-1].start()
    assert blocked["c"].wait(10)  # C is held at the gate by the queued capture although only A (shared) is inside
    assert log == []
    a_go.set()
    for t in threads:
        t.join(30)
    assert not any(t.is_alive() for t in threads), "the gate deadlocked"
    assert log[:3] == ["a work done", "b captures", "b capture done"]
    assert sorted(log[3:]) == ["a work again", "c work"]
    with capture_gate.hold():
        with pytest.raises(RuntimeError, match="holds the gate already"):
            with capture_gate.hold():
                pass


def test_a_split_inside_a_share_runs_in_that_share(monkeypatch):
    """A share that splits again (a library call that splits, inside a split) runs that split in its own thread:
    threads of its own would wait for the capture gate the share holds."""
    out = {}
    monkeypatch.setattr(ws, "_load_kernels", lambda device: None)  # the timeout below is for the gate, not a compile

    def outer(lo, hi):
        inner = ws.run_shares(lambda a, b: {"t": np.array([threading.get_ident()])}, 4, workers=2)
        return {"same": np.array([all(p["t"][0] == threading.get_ident() for p in inner)])}

    job = threading.Thread(target=lambda: out.update(r=ws.run_shares(outer, 4, workers=2)), daemon=True)
    job.start()
    job.join(60)
    assert not job.is_alive(), "a split inside a share hung"
    assert [bool(p["same"][0]) for p in out["r"]] == [True, True]


def test_an_error_in_a_share_reaches_the_caller():
    def share(lo, hi):
        if lo > 0:
            raise RuntimeError(f"share {lo}:{hi} failed")
        return {}

    with pytest.raises(RuntimeError, match="share 2:4 failed"):
        ws.run_shares(share, 4, workers=2)


def test_gait_run_over_threads_equals_one_batch():
    """Randomized worlds (every one different), 1 vs 2 vs 3 threads: displacements, flags, every gait metric and
    the saved frames of the first worlds (which straddle the shares at 3 threads) identical."""
    p = randomized_params("default", "omega", False, "analytic", 5, 11)
    kw = dict(settle=0.02, fps=50.0, save_worlds=3)
    one = run_gait_split(p, 5, 0.06, workers=1, **kw)
    assert one["sim"].use_graph  # one share: this thread, graphs as usual
    for w in (2, 3):
        r = run_gait_split(p, 5, 0.06, workers=w, **kw)
        for k in ("displacement_m", "unstable", "crumpled"):
            np.testing.assert_array_equal(one[k], r[k], err_msg=k)
        assert set(r["metrics"]) == set(one["metrics"])
        for k, v in one["metrics"].items():
            np.testing.assert_array_equal(v, r["metrics"][k], err_msg=k)
        assert set(r["frames"]) == set(one["frames"])
        for k, v in one["frames"].items():
            np.testing.assert_array_equal(v, r["frames"][k], err_msg=k)
        assert r["frames"]["positions"].shape[1] == 3
    assert np.ptp(one["displacement_m"]) > 0  # the worlds do differ: a mixed-up share would show


def test_kernels_load_once_per_device_before_any_share_starts(monkeypatch):
    """run_shares loads the kernel modules before its threads start (two threads must not load a module at once),
    and only the first time on a device: a loaded module stays loaded, so later splits skip the one-world run."""
    calls, starts = [], []
    monkeypatch.setattr(ws, "_load_kernels", lambda device: calls.append((str(device), len(starts))))
    monkeypatch.setitem(ws._loaded, "devices", set())
    for _ in range(3):
        ws.run_shares(lambda lo, hi: starts.append(lo) or {}, 4, workers=2)
    assert calls == [("cpu", 0)] and len(starts) == 6


def test_blas_runs_one_thread_inside_a_split_whatever_the_workers():
    """OpenBLAS's rounding depends on its thread count (and 2 threads spin on small solves), so a split holds it at
    one thread for 1 or 2 workers alike, and puts the caller's count back afterwards, nested or not."""
    if ws.blas_threads() is None:
        pytest.skip("NumPy's BLAS is not an OpenBLAS this module can set")
    get, put = ws._openblas()
    before = get()
    put(2)
    try:
        seen = []
        for workers in (1, 2):
            ws.run_shares(lambda lo, hi: seen.append(ws.blas_threads()) or {}, 4, workers=workers)
            with ws.one_blas_thread():
                with ws.one_blas_thread():
                    seen.append(ws.blas_threads())
                seen.append(ws.blas_threads())
            seen.append(("after", ws.blas_threads()))
        assert seen == [1, 1, 1, ("after", 2), 1, 1, 1, 1, ("after", 2)]
    finally:
        put(before)


def test_batched_linear_prediction_equals_the_per_world_one_bit_for_bit():
    """experiment compression / flexure's linear prediction (host NumPy, in each share after its simulation) for
    every world at once: the per-world reference function's numbers exactly, with every world's hinge and bar
    stiffness different."""
    from dataclasses import replace

    from warpworm.analysis import experiments as ex
    from warpworm.physics.params import WormParams
    from warpworm.sim.model import Model

    p = replace(WormParams(), hinge_stiffness=np.array([0.003, 0.01, 0.04]), bar_stiffness=np.array([15.0, 20.0, 30.0]))
    n = int(p.n_units)
    anchors = np.concatenate([ex.section_vertices(n, 0), ex.section_vertices(n, 2 * n)])
    model = Model.from_params(p, 3, "cpu", anchors=anchors, anchor_stiffness=1.0e4)
    off = np.zeros((len(anchors), 3))
    off[3:, 0] = -1.0e-6
    ref = np.stack([ex.linear_anchor_response(model, p, off, world=w) for w in range(3)])
    np.testing.assert_array_equal(ex.linear_anchor_responses(model, p, off), ref)
    pull = ref[:, 3:, 0].sum(axis=1)  # pushed along -x, the worm pulls the pusher back along +x, harder when stiffer
    assert np.all(pull > 0) and np.all(np.diff(pull) > 0)
