"""Two datasets' RGB against a converged render of the same scenes: which one is closer to the image it estimates.

``python3 benchmarks/rgb_against_reference.py A B calls.pkl [--samples 8]``

``A`` and ``B``: dataset folders written by ``warpworm generate`` with the same config and seed (e.g. by two trees);
``calls.pkl``: the render calls of that job (``job_render_replay.py capture calls.pkl CONFIG --num N OVERRIDES``, the
same overrides). The reference renders those calls again with ``--samples`` x ``--samples`` samples per pixel and no
texture filter (each sample its own ray through the lens, its own texture lookup), the same sensor values: where
A and B differ by their sampling (supersampling, the lens's resampling), the reference says which is right. Run it
with the sensor's noise off (``randomize.sensor.noise_std=0.0``), which no render can reproduce. Prints, per image,
the mean absolute difference in 8-bit levels of A - B, A - reference and B - reference (mean, max, and how many
images B is the closer one); exits 2 when the datasets and the calls do not hold the same scenes (their
segmentation, which no sampling changes, must equal the reference render's).
"""

from __future__ import annotations

import argparse
import pickle
import sys
from pathlib import Path

import numpy as np

from warpworm import quiet_warp
from warpworm.data.dataset import DatasetReader
from warpworm.render import rasterizer


def _levels(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Per-image mean |x - y| [8-bit levels] of two (N, H, W, 3) uint8 stacks."""
    return np.abs(x.astype(np.int16) - y.astype(np.int16)).mean(axis=(1, 2, 3))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("a", type=Path)
    ap.add_argument("b", type=Path)
    ap.add_argument("calls", type=Path)
    ap.add_argument("--samples", type=int, default=8, help="samples per pixel side of the reference (default 8)")
    args = ap.parse_args(argv)
    if args.samples < 1:
        ap.error(f"--samples: got {args.samples}; expected an integer >= 1")
    quiet_warp()
    with open(args.calls, "rb") as f:
        calls = pickle.load(f)
    outs = [rasterizer.Renderer(**{**settings, "supersample": args.samples, "texture_filter": False})
            .render(scene, cameras, **kw) for settings, scene, cameras, kw in calls]
    ref, ref_seg = (np.concatenate([o[k] for o in outs]) for k in ("rgb", "seg"))
    readers = [DatasetReader(p) for p in (args.a, args.b)]
    for name, r in zip("AB", readers):
        seg = r.read("segmentation")
        if seg.shape != ref_seg.shape or not np.array_equal(seg, ref_seg):
            print(f"{name}'s segmentation {seg.shape} is not the calls' {ref_seg.shape}: not the same scenes")
            return 2
    a, b = (r.read("rgb") for r in readers)
    ab, ar, br = _levels(a, b), _levels(a, ref), _levels(b, ref)
    for name, m in (("A - B", ab), ("A - reference", ar), ("B - reference", br)):
        print(f"{name:14s} per-image mean |difference| [levels]: mean {m.mean():.3f}, max {m.max():.3f}")
    worst = int(np.argmax(ab))
    print(f"B closer to the reference in {int((br < ar).sum())} of {len(br)} images; the images furthest apart "
          f"(#{worst}, {ab[worst]:.3f} levels): A {ar[worst]:.3f}, B {br[worst]:.3f} from the reference")
    return 0


if __name__ == "__main__":
    sys.exit(main())
