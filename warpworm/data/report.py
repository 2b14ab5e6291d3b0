"""What a dataset (or a domain-randomization sweep of several) contains: the spread of every randomized parameter and of
the labels, as JSON numbers and a PNG of histograms (``warpworm report DIR [DIR2 ...]``).

Quantities, per folder (every one from the shards' datasets):

* every ``params/<group>.<name>``: per sample; numbers as min / mean / max and a histogram, text and booleans as counts;
* crease angles ``creases/angle`` [deg], every crease of every sample;
* the crease-angle range within a trajectory [deg]: per trajectory, the largest over its creases of (max - min) over
  its frames: how far the worm folded and unfolded while it was filmed;
* the minimum deformation ratio of a trajectory (``labels/deformation``: distances between adjacent segment centres
  over their rest values; min over frames and segment pairs), and the fraction of trajectories whose minimum is
  <= 0.9 (a contraction of 10 % or more somewhere along the body);
* ``labels/visib_fract``; the projected worm box size sqrt(w h) [px] of ``labels/bbox_obj``; the camera's distance to
  the worm body origin [m] (``camera/position`` to the translation of ``poses/body``).

Images are never read, so a report of a large dataset costs a pass over its small label arrays only.
With several folders every quantity shares its histogram bins across the folders (one column per folder).
"""

from __future__ import annotations

import json
import math
import textwrap
from dataclasses import dataclass, field
from pathlib import Path

import h5py
import numpy as np

from warpworm.data import dataset as ds

CONTRACTION_THRESHOLD = 0.9
"""A trajectory counts as contracted when its minimum deformation ratio is <= this."""

BINS = 24

LABELS = (  # key, title (with unit)
    ("crease_angle_deg", "crease angle, every crease and sample [deg]"),
    ("crease_range_within_trajectory_deg", "crease-angle range within a trajectory [deg]"),
    ("min_deformation_per_trajectory", "min deformation ratio of a trajectory"),
    ("visib_fract", "visible fraction"),
    ("bbox_size_px", "projected box size sqrt(w h) [px]"),
    ("camera_distance_m", "camera distance to the worm body origin [m]"),
)

_READ = ("trajectory", "creases/angle", "labels/deformation", "labels/visib_fract", "labels/bbox_obj",
         "camera/position", "poses/body")


class ReportError(ValueError):
    """A folder is not a readable dataset (one line: the folder and why)."""


@dataclass
class FolderData:
    """The arrays a report needs from one dataset folder (per sample unless said)."""

    root: Path
    samples: int
    trajectories: int
    frames_per_trajectory: int
    values: dict[str, np.ndarray]  # LABELS keys -> 1-D values (per sample, per crease value or per trajectory)
    params: dict[str, np.ndarray] = field(default_factory=dict)  # params name -> per-sample values
    distributions: dict[str, object] = field(default_factory=dict)  # params name -> its config entry (manifest)


def within_trajectory_range(traj: np.ndarray, angle: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per trajectory (sorted unique ids), max over creases of (max - min over its frames) of ``angle`` (N, C)."""
    ids, inv = np.unique(traj, return_inverse=True)
    C = angle.shape[1]
    hi = np.full((len(ids), C), -np.inf)
    lo = np.full((len(ids), C), np.inf)
    np.maximum.at(hi, inv, angle)
    np.minimum.at(lo, inv, angle)
    return ids, (hi - lo).max(axis=1) if C else np.zeros(len(ids))


def per_trajectory_min(traj: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Per trajectory (sorted unique ids), the minimum of ``x`` (N, ...) over its samples and the trailing axes."""
    ids, inv = np.unique(traj, return_inverse=True)
    m = np.full(len(ids), np.inf)
    np.minimum.at(m, inv, x.reshape(len(x), -1).min(axis=1) if x.size else np.full(len(x), np.inf))
    return m


def load_folder(root) -> FolderData:
    """Read the label and parameter arrays of dataset folder ``root`` (every shard on disk). Raises ReportError."""
    root = Path(root)
    if not root.is_dir():
        raise ReportError(f"{root}: not a folder")
    try:
        reader = ds.open(root)
    except ds.DatasetError as exc:
        raise ReportError(f"{root}: not a dataset folder ({exc})") from None
    if not reader.shard_paths:
        raise ReportError(f"{root}: no shard-*.h5 in the folder (a job that has not finished a shard yet?)")
    cols: dict[str, list] = {k: [] for k in _READ}
    params: dict[str, list] = {}
    names: list[str] | None = None
    try:
        for p in reader.shard_paths:
            with h5py.File(p, "r") as f:
                if names is None:
                    names = json.loads(f.attrs.get("params_names", "[]"))
                for k in _READ:
                    cols[k].append(f[k][...])
                for n in names:
                    if f"params/{n}" in f:
                        params.setdefault(n, []).append(f[f"params/{n}"][...])
    except (OSError, KeyError) as exc:
        raise ReportError(f"{root}: unreadable shard or missing dataset ({type(exc).__name__}: {str(exc)[:160]}); "
                          f"run `warpworm verify {root}`") from None
    finally:
        reader.close()
    dists = {f"{g}.{n}": v for g, group in (reader.manifest.get("config", {}).get("randomize") or {}).items()
             if isinstance(group, dict) for n, v in group.items()}
    a = {k: np.concatenate(v) for k, v in cols.items()}
    traj = a["trajectory"]
    angle = np.degrees(a["creases/angle"].astype(np.float64))
    _, rng = within_trajectory_range(traj, angle)
    box = a["labels/bbox_obj"].astype(np.float64)
    body_origin = a["poses/body"][:, :3, 3]
    values = {
        "crease_angle_deg": angle.reshape(-1),
        "crease_range_within_trajectory_deg": rng,
        "min_deformation_per_trajectory": per_trajectory_min(traj, a["labels/deformation"].astype(np.float64)),
        "visib_fract": a["labels/visib_fract"].astype(np.float64),
        "bbox_size_px": np.sqrt(np.clip(box[:, 2], 0, None) * np.clip(box[:, 3], 0, None)),
        "camera_distance_m": np.linalg.norm(a["camera/position"] - body_origin, axis=1),
    }
    n_traj = len(np.unique(traj))
    F = len(traj) // n_traj if n_traj else 0
    return FolderData(root, len(traj), n_traj, F, values, {n: np.concatenate(v) for n, v in params.items()}, dists)


def _stats(x: np.ndarray) -> dict:
    x = np.asarray(x, dtype=np.float64)
    x = x[np.isfinite(x)]
    if not x.size:
        return {"count": 0, "min": None, "mean": None, "median": None, "max": None}
    return {"count": int(x.size), "min": float(x.min()), "mean": float(x.mean()), "median": float(np.median(x)),
            "max": float(x.max())}


def _is_numeric(v: np.ndarray) -> bool:
    return v.dtype.kind in "fiu"


def _as_text(v: np.ndarray) -> np.ndarray:
    if v.dtype.kind == "S":
        return np.char.decode(v, "utf-8")
    return v.astype(str)


def folder_summary(d: FolderData) -> dict:
    """The JSON numbers of one folder."""
    mins = d.values["min_deformation_per_trajectory"]
    out = {
        "dir": str(d.root),
        "samples": d.samples,
        "trajectories": d.trajectories,
        "frames_per_trajectory": d.frames_per_trajectory,
        "crease_range_within_trajectory_deg": _stats(d.values["crease_range_within_trajectory_deg"]),
        "min_deformation_per_trajectory": _stats(mins),
        "fraction_trajectories_min_deformation_le_0.9":
            float(np.mean(mins <= CONTRACTION_THRESHOLD)) if mins.size else None,
        "crease_angle_deg": _stats(d.values["crease_angle_deg"]),
        "visib_fract": _stats(d.values["visib_fract"]),
        "bbox_size_px": _stats(d.values["bbox_size_px"]),
        "camera_distance_m": _stats(d.values["camera_distance_m"]),
        "params": {},
    }
    for n, v in sorted(d.params.items()):
        if _is_numeric(v):
            s = _stats(v)
            out["params"][n] = {"min": s["min"], "mean": s["mean"], "max": s["max"]}
        else:
            t = _as_text(v)
            u, c = np.unique(t, return_counts=True)
            out["params"][n] = {"counts": {str(a): int(b) for a, b in zip(u, c)}}
        out["params"][n]["config"] = d.distributions.get(n)  # None: the parameter's default
    return out


def config_differs(folders: list[FolderData], names) -> list[str]:
    """Parameters whose config entry (distribution) is not the same in every folder: what a sweep changed."""
    if len(folders) < 2:
        return []
    return [n for n in names
            if len({json.dumps(f.distributions.get(n), sort_keys=True, default=str) for f in folders}) > 1]


def _varies(folders: list[FolderData], name: str) -> bool:
    """Whether parameter ``name`` takes more than one value across the folders (constants are listed, not plotted)."""
    vals = [f.params[name] for f in folders if name in f.params]
    if not vals:
        return False
    if all(_is_numeric(v) for v in vals):
        x = np.concatenate([v.astype(np.float64) for v in vals])
        x = x[np.isfinite(x)]
        return x.size > 0 and x.max() > x.min()
    return len(np.unique(np.concatenate([_as_text(v) for v in vals]))) > 1


def _constant_text(folders: list[FolderData], name: str) -> str:
    for f in folders:
        if name in f.params and len(f.params[name]):
            v = f.params[name][0]
            if isinstance(v, bytes):
                return v.decode()
            return f"{float(v):.4g}" if _is_numeric(f.params[name]) else str(v)
    return "?"


def shared_bins(arrays: list[np.ndarray], bins: int = BINS) -> np.ndarray:
    """Bin edges spanning every finite value of every array (one set for a row of the side-by-side figure)."""
    x = np.concatenate([np.asarray(a, dtype=np.float64).reshape(-1) for a in arrays]) if arrays else np.zeros(0)
    x = x[np.isfinite(x)]
    if not x.size:
        return np.linspace(0, 1, bins + 1)
    lo, hi = float(x.min()), float(x.max())
    if hi <= lo:
        pad = abs(lo) * 0.05 or 0.5
        lo, hi = lo - pad, hi + pad
    return np.linspace(lo, hi, bins + 1)


def build(dirs, out) -> tuple[dict, Path, Path | None, str | None]:
    """Load every folder, write ``OUT.json`` and (with matplotlib) ``OUT.png``.

    Returns (report dict, json path, png path or None, note or None). Raises ReportError for a bad folder.
    """
    folders = [load_folder(d) for d in dirs]
    out = Path(out)
    if out.suffix in (".png", ".json"):
        out = out.with_suffix("")
    out.parent.mkdir(parents=True, exist_ok=True)
    names = sorted(set().union(*(f.params for f in folders)))
    differs = config_differs(folders, names)
    varying = [n for n in names if _varies(folders, n)]
    varying = [n for n in differs if n in varying] + [n for n in varying if n not in differs]  # the sweep's first
    constant = [n for n in names if n not in varying]
    report = {
        "format": "warpworm-report", "version": 1,
        "contraction_threshold": CONTRACTION_THRESHOLD,
        "folders": [folder_summary(f) for f in folders],
        "params_config_differs": differs,
        "params_varying": varying,
        "params_constant": {n: _constant_text(folders, n) for n in constant},
        "bins": {},
        "png": None,
    }
    rows = [(k, t, [f.values[k] for f in folders]) for k, t in LABELS]
    for k, _, arrays in rows:
        extra = [np.array([CONTRACTION_THRESHOLD])] if k == "min_deformation_per_trajectory" else []
        report["bins"][k] = shared_bins(arrays + extra).tolist()
    png, note = out.with_suffix(".png"), None
    try:
        import matplotlib  # optional dependency: matplotlib (the plots extra)
    except ImportError:
        png, note = None, ("note: the PNG needs the plots extra (pip install 'warpworm[plots]'); wrote the JSON "
                           "only")
    else:
        matplotlib.use("Agg", force=True)
        _plot(folders, rows, varying, constant, report, png, set(differs))
        report["png"] = str(png)
    jpath = out.with_suffix(".json")
    ds.atomic_write_json(jpath, report)
    return report, jpath, png, note


def _short(path: Path, n: int = 38) -> str:
    s = str(path)
    return s if len(s) <= n else "…" + s[-(n - 1):]


def _plot(folders, rows, varying, constant, report, png: Path, differs=frozenset()) -> None:
    import matplotlib.pyplot as plt  # optional dependency: matplotlib (the plots extra)
    from matplotlib.ticker import MaxNLocator  # optional dependency: matplotlib (the plots extra)

    nf = len(folders)
    CW = 3.6  # [in] per column
    panels = [(t, arrays, report["bins"][k], k) for k, t, arrays in rows]
    for n in varying:
        arrays = [f.params.get(n, np.zeros(0)) for f in folders]
        panels.append((f"params/{n}" + (" [config differs]" if n in differs else ""), arrays,
                       None, n))
    # a grid of panels, 4 across; several folders share each panel (one colour each, shared bins), so the picture
    # stays the size of one folder's (it was a column per folder and a row per quantity: 720 x 9542 px for two)
    ncol = 4
    nrow = math.ceil(len(panels) / ncol)

    lines = []
    for f in report["folders"]:
        r = f["crease_range_within_trajectory_deg"]
        frac = f["fraction_trajectories_min_deformation_le_0.9"]
        lines.append(f"{_short(Path(f['dir']), 60)}: {f['samples']} samples, {f['trajectories']} trajectories; "
                     "crease range within a trajectory: median "
                     + (f"{r['median']:.1f} deg" if r["median"] is not None else "-")
                     + "; min deformation <= 0.9 in "
                     + (f"{100 * frac:.0f} % of trajectories" if frac is not None else "-"))
    if constant:
        lines.append("constant (not plotted): "
                     + ", ".join(f"{n}={report['params_constant'][n]}" for n in constant))
    width_chars = int(CW * ncol * 15)
    text = "\n".join(textwrap.fill(line, width_chars, subsequent_indent="  ") for line in lines)
    text_h = 0.13 * (text.count("\n") + 1) + 0.15  # [in]
    legend_h = 0.18 * nf if nf > 1 else 0.0
    H = 2.3 * nrow + 0.7 + legend_h + text_h
    fig, axes = plt.subplots(nrow, ncol, figsize=(CW * ncol, H), squeeze=False)
    colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]

    def ax_for(i, j):
        return axes[i // ncol][i % ncol]

    for i, (title, arrays, edges, key) in enumerate(panels):
        numeric = all(_is_numeric(a) for a in arrays if len(a))
        if numeric and edges is None:
            edges = shared_bins([a.astype(np.float64) for a in arrays])
        cats = None
        if not numeric:
            cats = sorted(set().union(*(set(_as_text(a).tolist()) for a in arrays)))
        ymax = 0
        for j, a in enumerate(arrays):
            ax = ax_for(i, j)
            c = colors[j % len(colors)]
            if numeric:
                x = a.astype(np.float64)
                x = x[np.isfinite(x)]
                h, _ = np.histogram(x, bins=edges)
                if nf == 1:
                    ax.stairs(h, edges, fill=True, color=c, alpha=0.75)
                else:
                    ax.stairs(h, edges, fill=False, color=c, lw=1.6)
                ymax = max(ymax, int(h.max()) if h.size else 0)
                if key == "min_deformation_per_trajectory":
                    ax.axvline(CONTRACTION_THRESHOLD, color="k", lw=0.8, ls="--")
                if x.size:
                    ax.text(0.98, 0.95 - 0.17 * j, f"n={x.size}\n[{x.min():.3g}, {x.max():.3g}]",
                            transform=ax.transAxes, ha="right", va="top", fontsize=7, color=c if nf > 1 else "k")
            else:
                t = _as_text(a)
                cnt = [int(np.sum(t == v)) for v in cats]
                width = 0.8 / nf
                ax.bar(np.arange(len(cats)) + (j - (nf - 1) / 2) * width, cnt, width=width, color=c, alpha=0.75)
                ax.set_xticks(range(len(cats)), cats, fontsize=7)
                ymax = max(ymax, max(cnt, default=0))
            if j == 0:
                ax.set_title(title, fontsize=8, loc="left")
            ax.tick_params(labelsize=7)
            ax.yaxis.set_major_locator(MaxNLocator(3, integer=True))
            if numeric:
                ax.xaxis.set_major_locator(MaxNLocator(5))
        for j in range(len(arrays)):  # shared y scale within a row
            ax_for(i, j).set_ylim(0, max(1, ymax) * 1.25)
    for i in range(len(panels), nrow * ncol):
        ax_for(i, 0).axis("off")
    fig.suptitle("warpworm report: " + ("one colour per folder, shared bins" if nf > 1 else
                 _short(folders[0].root, 80)), fontsize=11, x=0.01, y=1 - 0.12 / H, ha="left", va="top")
    for j, f in enumerate(folders if nf > 1 else []):
        fig.text(0.01, 1 - (0.5 + 0.18 * j) / H, f"\u25a0 {_short(f.root, 90)}", fontsize=9, fontweight="bold",
                 color=colors[j % len(colors)], ha="left", va="top")
    fig.text(0.01, 0.05 / H, text, fontsize=7, va="bottom", ha="left", family="monospace")
    # fixed margins in inches (tight_layout costs as much as drawing here)
    top_in = 0.55 + legend_h
    fig.subplots_adjust(left=0.35 / (CW * ncol), right=1 - 0.15 / (CW * ncol), top=1 - top_in / H,
                        bottom=(text_h + 0.3) / H, hspace=0.5, wspace=0.22)
    fig.savefig(png, dpi=80)
    plt.close(fig)


def text_summary(report: dict) -> str:
    """A few lines for the terminal."""
    out = []
    for s in report["folders"]:
        r = s["crease_range_within_trajectory_deg"]
        frac = s["fraction_trajectories_min_deformation_le_0.9"]
        rng = (f"median {r['median']:.2f}, min {r['min']:.2f}, max {r['max']:.2f}" if r["count"] else "none")
        out.append(f"{s['dir']}: {s['samples']} samples, {s['trajectories']} trajectories; crease-angle range within "
                   f"a trajectory [deg]: {rng}; trajectories with min deformation <= 0.9: "
                   f"{'-' if frac is None else f'{100 * frac:.1f} %'}")
    out.append(f"parameters: {len(report['params_varying'])} varying, {len(report['params_constant'])} constant"
               + (f"; config differs between the folders: {', '.join(report['params_config_differs'])}"
                  if len(report["folders"]) > 1 else ""))
    return "\n".join(out)


__all__ = ["build", "load_folder", "folder_summary", "within_trajectory_range", "per_trajectory_min", "ReportError",
           "text_summary", "CONTRACTION_THRESHOLD"]
