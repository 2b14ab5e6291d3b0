#!/usr/bin/env python
"""What if the EPM kept §III's placement every cycle? A path that re-aims each closest approach at the worm.

``benchmarks/gait_cycles.py`` shows that with the paper's sinusoidal path the worm slides toward the approaching EPM
and the placement at closest approach settles where the pulls balance, not where §III puts it. This runs the other
experiment: a tracking path. At each far point (s = c) it reads every world's IPM positions and gives the next cycle
the advance w_c = 2 (x_target − x_EPM), so that the EPM (on the same gap profile h + a (1 + cos 2πs) / 2, its x
continuous) passes under ``x_centre + P (x_head − x_centre)`` at s = c + ½ if the worm stood still. It is a
controller reading the state once per cycle (the worm still moves during the approach), not the paper's open-loop
path. Every placement P of ``--place`` is one world of one batch.

Usage::

    python benchmarks/gait_tracking.py peristaltic --place 0.4 [--a 45 --h 5] [--cycles 6]
    python benchmarks/gait_tracking.py peristaltic --place=-0.4,-0.2,0,0.2,0.4,0.6,0.8,1.0

Prints, per world and cycle: the EPM's advance [mm], the smallest segment ratios (tail → head), the tail's and
head's motion [mm]; then per placement the net tail and head motion.
"""

from __future__ import annotations

import argparse
import copy
import sys
from dataclasses import replace

import numpy as np

from warpworm import quiet_warp
from warpworm.analysis.gait_metrics import end_centres, segment_ratios
from warpworm.physics import gaits
from warpworm.physics.params import EPM, IPM_CENTRE, IPM_HEAD
from warpworm.sim.model import Model
from warpworm.sim.simulator import Simulator


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("gait", choices=gaits.GAITS)
    ap.add_argument("--place", required=True,
                    help="target placements, comma-separated (0 centre IPM, 1 head IPM): one world each")
    ap.add_argument("--a", type=float, default=None, help="amplitude [mm] (default the preset's)")
    ap.add_argument("--h", type=float, default=None, help="closest approach [mm] (default the preset's)")
    ap.add_argument("--cycles", type=int, default=6)
    args = ap.parse_args(argv)
    if args.cycles < 1:
        raise SystemExit(f"--cycles: {args.cycles}; expected at least 1")
    try:
        place = np.array([float(v) for v in args.place.split(",") if v.strip()])
    except ValueError:
        raise SystemExit(f"--place: {args.place!r} is not a comma-separated list of numbers") from None
    if len(place) == 0 or not np.all(np.isfinite(place)):
        raise SystemExit(f"--place: {args.place!r}: expected one or more finite numbers")
    quiet_warp()
    over = {}
    if args.a is not None:
        over["amplitude"] = args.a * 1e-3
    if args.h is not None:
        over["closest_approach"] = args.h * 1e-3
    params = gaits.preset_params(args.gait, magnet_model="analytic", **over)
    params = replace(params, support_thickness=min(float(params.support_thickness),
                                                   float(np.min(params.closest_approach))))
    W = len(place)
    model = Model.from_params(params, W, "cpu")
    sim = Simulator(model, dt=gaits.DEFAULT_DT, substeps=gaits.DEFAULT_SUBSTEPS)
    state = sim.initial_state()
    sim.settle(state, 0.2)
    path = copy.deepcopy(sim.control.path)
    period = float(np.asarray(path.period).reshape(-1)[0])
    phase = np.asarray(path.phase, np.float64)
    steps_per_cycle = int(round(period / sim.dt))
    frame_times = sim.dt * np.arange(5, steps_per_cycle + 1, 5)  # a cycle's frames, every 5 steps (20 ms)
    pattern = model.pattern
    x_first = state.positions.numpy().astype(np.float64)
    for f in ("amplitude", "depth", "theta", "period", "phase", "start_y"):  # every field per world
        setattr(path, f, np.broadcast_to(np.asarray(getattr(path, f), np.float64).reshape(-1), (W,)).copy())
    path.direction = np.ones(W)
    print(f"{args.gait}: tracking path; per world and cycle: EPM advance | smallest segment ratios (tail -> head) | "
          f"tail, head motion [mm]")
    net = np.zeros((W, 2))
    for c in range(args.cycles):
        mags = state.magnet_pos.numpy().astype(np.float64)  # (W, 4, 3)
        x_epm = mags[:, EPM, 0]
        target = mags[:, IPM_CENTRE, 0] + place * (mags[:, IPM_HEAD, 0] - mags[:, IPM_CENTRE, 0])
        w_c = 2.0 * (target - x_epm)  # this cycle's advance: under the target at s = c + 1/2
        path.wavelength = w_c
        path.start_x = x_epm - w_c * (c + phase)  # x(s = c) = x_epm: the path stays continuous
        sim.control.set_path(path)
        x_start = state.positions.numpy().astype(np.float64)
        x = sim.run(state, frame_times, keys=("positions",), stack=True)["positions"].astype(np.float64)  # (F, W, V, 3)
        rmin = segment_ratios(pattern, np.concatenate([x_first[None], x]))[1:].min(axis=0)  # (W, 4)
        tail, head = end_centres(pattern, np.stack([x_start, x[-1]]))  # (2, W, 3)
        d_tail = 1e3 * (tail[1, :, 0] - tail[0, :, 0])
        d_head = 1e3 * (head[1, :, 0] - head[0, :, 0])
        net += np.stack([d_tail, d_head], -1)
        bad = state.unstable.numpy() != 0
        for i in range(W):  # printing only
            print(f"  P {place[i]:+.2f} cycle {c}: {1e3 * w_c[i]:+6.1f} mm | {' '.join(f'{v:.3f}' for v in rmin[i])} | "
                  f"{d_tail[i]:+6.2f} {d_head[i]:+6.2f}{'  UNSTABLE' if bad[i] else ''}", flush=True)
    for i in range(W):
        print(f"P {place[i]:+.2f}: net tail {net[i, 0]:+.1f} mm, head {net[i, 1]:+.1f} mm over {args.cycles} cycles")
    return 0


if __name__ == "__main__":
    sys.exit(main())
