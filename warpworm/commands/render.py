"""``warpworm render``: simulate (or pose) W worlds, render C cameras each, compute labels, write a contact sheet.

Outputs in ``--out``:
- ``contact_sheet.png``: one row per image (RGB | depth colour map | segmentation overlay with keypoints, boxes and
  the body axes), for the first ``--sheet-rows`` images;
- ``labels.npz``: every label array of :func:`warpworm.render.labels.schema_labels`, under the dataset schema's
  names (leading axis = image), plus ``rgb``, ``depth`` [m] (0 = background), ``seg`` and ``keypoint_names``.

Every draw is the default dataset config's: the worlds' parameters (:func:`warpworm.data.sampling.randomized_params`),
their look (:func:`warpworm.data.sampling.sample_appearance`) and sensor effects, through the one counter-based generator.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from warpworm.commands.common import check_minimum, device_option, first_run_notice, refuse
from warpworm.data import export_json as strict_json
from warpworm.data import sampling
from warpworm.data.config import check_options, load_config
from warpworm.physics import gaits
from warpworm.render import Renderer, sample_cameras, scene_from_snapshot
from warpworm.render.contact_sheet import contact_sheet, save_png
from warpworm.render.demo import default_pattern, posed_worm_states
from warpworm.render.labels import KEYPOINT_NAMES, schema_labels
from warpworm.render.sensor import apply_sensor
from warpworm.rng import derive_seeds
from warpworm.sim.model import Model
from warpworm.sim.simulator import Simulator

HELP = "render W worlds from C seeded cameras each (RGB, depth, segmentation, labels) and write a contact sheet PNG"


def add_arguments(parser) -> None:
    parser.add_argument("--worlds", type=int, default=4, help="number of worlds W (default 4)")
    parser.add_argument("--cameras", type=int, default=2, help="cameras per world C (default 2)")
    parser.add_argument("--out", default="render_out", help="output folder (default ./render_out)")
    parser.add_argument("--size", type=int, default=256, help="image width = height [px] (default 256)")
    parser.add_argument("--seed", type=int, default=0, help="master seed (parameters, appearance, cameras, poses, "
                        "sensor), as a dataset job's --seed")
    parser.add_argument("--config", default="default", help="dataset config whose distributions are drawn from")
    parser.add_argument("--source", choices=["sim", "posed"], default="sim",
                        help="sim: run the simulator's gait for --sim-time; posed: bent rest worms (no physics)")
    parser.add_argument("--gait", choices=["peristaltic", "omega", "inchworm"], default="peristaltic")
    parser.add_argument("--sim-time", type=float, default=0.15,
                        help="simulated gait time after settling [s] (default 0.15)")
    parser.add_argument("--device", default=None, help="Warp device for simulation and rendering (default Warp's)")
    parser.add_argument("--sensor", action="store_true", help="apply seeded sensor effects to the RGB column")
    parser.add_argument("--sheet-rows", type=int, default=8, help="images shown in the contact sheet (default 8)")
    parser.add_argument("--json", action="store_true", help="print a JSON summary only")


def simulate_states(cfg, num_worlds: int, seed: int, gait: str, sim_time: float, device=None) -> tuple[dict, object]:
    """Run ``gait`` on W worlds drawn as a dataset job of ``cfg`` with master ``seed`` draws its trajectories
    (material, magnets, EPM path; :func:`warpworm.data.sampling.randomized_params`); ``cfg`` draws ``gait`` only.

    Returns (snapshot dict, model).
    """

    p = sampling.randomized_params(cfg, num_worlds, seed)
    if np.any(np.asarray(p.gait) != gait):
        raise ValueError(f"randomize.worm.gait: the config draws {p.gait!r}; expected {gait!r}")
    model = Model.from_params(p, num_worlds, device)
    sim = Simulator(model, dt=gaits.DEFAULT_DT, substeps=gaits.DEFAULT_SUBSTEPS)
    state = sim.initial_state()
    sim.settle(state, 0.1)
    return sim.run(state, [max(0.0, sim_time)])[0], model


def main(args) -> int:
    out = Path(args.out)
    try:  # the rules generate applies (warpworm.data.config), before any work
        check_options({"--worlds": (args.worlds, "sim.worlds"), "--size": (args.size, "render.width")})
        check_minimum(cameras=(args.cameras, 1), sheet_rows=(args.sheet_rows, 1), sim_time=(args.sim_time, 0.0),
                      seed=(args.seed, 0))
        args.device = device_option(args.device)
        cfg = load_config(args.config, [f"randomize.worm.gait={args.gait}"], seed=int(args.seed))
        if out.exists() and not out.is_dir():
            raise ValueError(f"--out: got '{out}'; expected a folder (it is a file)")
    except ValueError as exc:
        return refuse(exc)

    first_run_notice(("warpworm.kernels.implicit_euler", "warpworm.render.raster_kernels"))
    out.mkdir(parents=True, exist_ok=True)
    W, C, S = int(args.worlds), int(args.cameras), int(args.size)
    t0 = time.perf_counter()
    notes = []
    params = None
    rest = None
    if args.source == "sim":
        states, model = simulate_states(cfg, W, args.seed, args.gait, args.sim_time, args.device)
        pattern, params, rest = model.pattern, model.params, model.rest_positions_host
        bad = np.asarray(states["unstable"]) | ~np.isfinite(states["positions"]).all(axis=(1, 2))
        if bad.any():
            # an unstable world has no trustworthy shape: show a posed rest worm instead, and say so
            posed = posed_worm_states(derive_seeds(args.seed, W, 3)[bad], pattern)
            for k in ("positions", "magnet_pos", "magnet_rot", "crease_angle", "bar_strain"):
                states[k] = np.asarray(states[k], dtype=np.float64).copy()
                states[k][bad] = posed[k]
            notes.append(f"{int(bad.sum())} of {W} simulated worlds were flagged unstable and are shown as posed "
                         f"rest worms instead: worlds {np.nonzero(bad)[0].tolist()}")
    else:
        pattern = default_pattern()
        states = posed_worm_states(derive_seeds(args.seed, W, 3), pattern)
    t_sim = time.perf_counter() - t0

    appearance = sampling.sample_appearance(cfg, np.arange(W))
    scene = scene_from_snapshot(states, pattern, params, appearance=appearance)
    N = W * C
    cams = sample_cameras(derive_seeds(args.seed, N, 2), states["positions"], width=S, height=S,
                          world_index=np.arange(N) // C)
    t1 = time.perf_counter()
    renderer = Renderer(S, S, device=args.device)
    images = renderer.render(scene, cams)
    t_render = time.perf_counter() - t1
    labels = schema_labels(states, pattern, cams, images, rest_positions=rest,
                           ipm_diameter=1e-2 if params is None else params.ipm_diameter)
    shown = None
    if args.sensor:
        rows = cams.world[: args.sheet_rows]
        values = sampling.sensor_values(sampling.appearance_draws(cfg, np.asarray(rows)))
        shown = apply_sensor(images["rgb"][: args.sheet_rows], derive_seeds(args.seed, N, 4)[: args.sheet_rows],
                             values=values)
    titles = [f"world {w} cam {i % C}" for i, w in enumerate(cams.world)]
    sheet = contact_sheet({**images, "camera/K": cams.K, "camera/R": cams.R, "camera/t": cams.t}, labels, rgb=shown,
                          max_rows=args.sheet_rows, titles=titles, scale=max(1.0, 192.0 / S))
    save_png(out / "contact_sheet.png", sheet)
    np.savez_compressed(out / "labels.npz", rgb=images["rgb"], depth=images["depth"], seg=images["seg"],
                        keypoint_names=np.array(KEYPOINT_NAMES), **labels)  # keys as the dataset's, e.g. "poses/body"
    summary = {
        "worlds": W, "images": N, "size": S, "source": args.source, "cameras_accepted": int(cams.accepted.sum()),
        "sim_or_pose_s": round(t_sim, 3), "render_s": round(t_render, 3),
        "visible_keypoints": int((labels["keypoints/visibility"] == 2).sum()),
        "occluded_keypoints": int((labels["keypoints/visibility"] == 1).sum()),
        "outside_keypoints": int((labels["keypoints/visibility"] == 0).sum()),
        "mean_visible_fraction": float(labels["labels/visib_fract"].mean()),
        "files": [str(out / "contact_sheet.png"), str(out / "labels.npz")], "notes": notes,
    }
    if args.json:
        print(strict_json.dumps(summary))
        return 0
    for n in notes:
        print("note:", n)
    print(f"rendered {N} images ({W} worlds x {C} cameras) at {S}x{S} in {t_render:.2f} s "
          f"(includes Warp kernel load/compile on first use); {summary['cameras_accepted']}/{N} views met the "
          f"in-frame rule")
    print(f"keypoints: {summary['visible_keypoints']} visible, {summary['occluded_keypoints']} occluded, "
          f"{summary['outside_keypoints']} outside; mean worm visible fraction {summary['mean_visible_fraction']:.2f}")
    print(f"wrote {out / 'contact_sheet.png'} and {out / 'labels.npz'}")
    return 0
