#!/usr/bin/env python
"""What if the EPM kept §III's placement every cycle? A path that re-aims each closest approach at the worm.

``benchmarks/gait_cycles.py`` shows that with the paper's sinusoidal path the worm slides toward the approaching EPM
and the placement at closest approach settles where the pulls balance, not where §III puts it. This runs the other
experiment: a tracking path. At each far point (s = c) it reads every world's IPM positions and gives the next cycle
the advance w_c = 2 (x_target − x_EPM), so that the EPM (on the same gap profile h + a (1 + cos 2πs) / 2, its x
continuous) passes under ``x_centre + P (x_head − x_centre)`` at s = c + ½ if the worm stood still. It is a
controller reading the state once per cycle (the worm still moves during the approach), not the paper's open-loop
path; one batch of W identical worlds (the per-world arithmetic is vectorized).

Usage::

    python benchmarks/gait_tracking.py peristaltic --place 0.4 [--a 45 --h 5] [--cycles 6]

Prints, per cycle: the EPM's advance [mm], the smallest segment ratios (tail → head), the tail's and head's
motion [mm].
"""

from __future__ import annotations

import argparse
import copy
import sys

import numpy as np


def main(argv=None) -> int:
    from warpworm import gaits, quiet_warp
    from warpworm.gait_metrics import end_centres, segment_ratios
    from warpworm.model import Model
    from warpworm.params import EPM, IPM_CENTRE, IPM_HEAD
    from warpworm.simulator import Simulator

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("gait", choices=gaits.GAITS)
    ap.add_argument("--place", type=float, required=True, help="target placement (0 centre IPM, 1 head IPM)")
    ap.add_argument("--a", type=float, default=None, help="amplitude [mm] (default the preset's)")
    ap.add_argument("--h", type=float, default=None, help="closest approach [mm] (default the preset's)")
    ap.add_argument("--cycles", type=int, default=6)
    args = ap.parse_args(argv)
    if args.cycles < 1:
        raise SystemExit(f"--cycles: {args.cycles}; expected at least 1")
    quiet_warp()
    over = {}
    if args.a is not None:
        over["amplitude"] = args.a * 1e-3
    if args.h is not None:
        over["closest_approach"] = args.h * 1e-3
    params = gaits.preset_params(args.gait, magnet_model="analytic", **over)
    params.support_thickness = min(float(params.support_thickness), float(np.min(params.closest_approach)))
    model = Model.from_params(params, 1, "cpu")
    sim = Simulator(model, dt=gaits.DEFAULT_DT, substeps=gaits.DEFAULT_SUBSTEPS)
    state = sim.initial_state()
    sim.settle(state, 0.2)
    path = copy.deepcopy(sim.control.path)
    period = float(np.asarray(path.period).reshape(-1)[0])
    phase = np.asarray(path.phase, np.float64)
    steps_per_cycle = int(round(period / sim.dt))
    chunk = 5
    pattern = model.pattern
    x_first = state.positions.numpy().astype(np.float64)
    print(f"{args.gait}: tracking path, placement {args.place:+.2f}; per cycle: EPM advance | smallest segment "
          f"ratios (tail -> head) | tail, head motion [mm]")
    for c in range(args.cycles):
        mags = state.magnet_pos.numpy().astype(np.float64)  # (W, 4, 3)
        x_epm = mags[:, EPM, 0]
        target = mags[:, IPM_CENTRE, 0] + args.place * (mags[:, IPM_HEAD, 0] - mags[:, IPM_CENTRE, 0])
        w_c = 2.0 * (target - x_epm)  # this cycle's advance: under the target at s = c + 1/2
        path.wavelength = w_c
        path.start_x = x_epm - w_c * (c + phase)  # x(s = c) = x_epm: the path stays continuous
        path.direction = np.ones_like(w_c)
        sim.control.set_path(path)
        tail0, head0 = end_centres(pattern, state.positions.numpy()[None].astype(np.float64))
        rmin = np.ones((len(w_c), 4))
        for _ in range(steps_per_cycle // chunk):
            sim.step(state, chunk)
            x = state.positions.numpy().astype(np.float64)
            rmin = np.minimum(rmin, segment_ratios(pattern, np.stack([x_first, x]))[1])
        tail1, head1 = end_centres(pattern, state.positions.numpy()[None].astype(np.float64))
        bad = int(np.count_nonzero(state.unstable.numpy()))
        print(f"  cycle {c}: {1e3 * w_c[0]:+6.1f} mm | {' '.join(f'{v:.3f}' for v in rmin[0])} | "
              f"{1e3 * (tail1[0, 0, 0] - tail0[0, 0, 0]):+6.2f} {1e3 * (head1[0, 0, 0] - head0[0, 0, 0]):+6.2f}"
              f"{'  UNSTABLE' if bad else ''}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
