"""Figures of the virtual experiments (:mod:`warpworm.analysis.experiments`), matplotlib with the Agg backend.

matplotlib is the optional ``plots`` extra (``pip install -e .[plots]``); it is imported only when a plot is drawn,
with a clear error when it is missing. Each ``plot_<name>(result, path)`` writes one PNG and returns its path.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

GAIT_COLORS = {"peristaltic": "tab:blue", "omega": "tab:orange", "inchworm": "tab:green"}


def _plt():
    try:
        import matplotlib  # optional dependency: matplotlib (the plots extra)
    except ImportError as exc:  # pragma: no cover - depends on the environment
        raise RuntimeError("plots need matplotlib: install the 'plots' extra (pip install -e '.[plots]')") from exc
    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt  # optional dependency: matplotlib (the plots extra)

    return plt


def _save(fig, path) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110, bbox_inches="tight")
    import matplotlib.pyplot as plt  # optional dependency: matplotlib (the plots extra)

    plt.close(fig)
    return path


def plot_force_distance(r: dict, path) -> Path:
    plt = _plt()
    fig, (a, b) = plt.subplots(1, 2, figsize=(11, 4.2))
    g = 1e3 * r["gap"]
    a.plot(g, r["analytic"], "k-", lw=2, label="analytic (exact)")
    for d, f in zip(r["densities"], r["dipoles"]):
        a.plot(g, f, "--", label=f"dipoles {d / 1e6:g}/cm³")
    a.plot(1e3 * r["table_gap"], r["table_force"], "o", mfc="none", mec="r", ms=8, label="closed-form table")
    a.set_xscale("log"), a.set_yscale("log")
    a.set_xlabel("face gap [mm]"), a.set_ylabel("attraction [N]")
    a.set_title("Two 1 cm³ N52 cubes, 0.9 A·m², unlike poles facing")
    a.legend(fontsize=8), a.grid(True, which="both", alpha=0.3)
    for d, f in zip(r["densities"], r["dipoles"]):
        b.plot(g, 100 * (f / r["analytic"] - 1.0), label=f"dipoles {d / 1e6:g}/cm³")
    b.plot(1e3 * r["table_gap"], 100 * (r["analytic_at_table"] / r["table_force"] - 1.0), "ko", ms=4,
           label="analytic vs table")
    b.set_xscale("log"), b.set_yscale("symlog", linthresh=0.01)
    b.set_xlabel("face gap [mm]"), b.set_ylabel("relative error vs analytic [%]")
    b.set_title("Dipole-model error"), b.legend(fontsize=8), b.grid(True, which="both", alpha=0.3)
    return _save(fig, path)


def _quasi_static_plot(r: dict, path, title: str, xlabel: str) -> Path:
    plt = _plt()
    fig, (a, b) = plt.subplots(1, 2, figsize=(11, 4.2))
    cmap = plt.get_cmap("viridis")
    ks = r["hinge_stiffness"]
    for w, k in enumerate(ks):
        c = cmap(w / max(1, len(ks) - 1))
        a.plot(1e3 * r["displacement"][:, w], 1e3 * r["force"][:, w], "o-", color=c, label=f"k_α = {k:g} N/rad")
        b.plot(1e3 * r["prescribed"][1:], 1e3 * r["linear"][1:, w], "o--", color=c, label=f"k_α = {k:g}")
    a.set_xlabel(xlabel), a.set_ylabel("force [mN]"), a.set_title(title + ": simulated")
    a.legend(fontsize=8), a.grid(alpha=0.3)
    b.set_xlabel(xlabel), b.set_ylabel("force [mN]"), b.set_yscale("log")
    b.set_title("linear quasi-static prediction (EA bars, no gravity)"), b.legend(fontsize=8), b.grid(alpha=0.3)
    return _save(fig, path)


def plot_compression(r: dict, path) -> Path:
    return _quasi_static_plot(r, path, "Compression", "shortening [mm]")


def plot_flexure(r: dict, path) -> Path:
    return _quasi_static_plot(r, path, "3-point flexure", "centre deflection [mm]")


def plot_slope(r: dict, path) -> Path:
    plt = _plt()
    fig, (a, b) = plt.subplots(1, 2, figsize=(11, 4.2))
    cmap = plt.get_cmap("coolwarm")
    off = r["offsets_deg"]
    span = max(1e-9, np.abs(off).max())
    for w, (be, o) in enumerate(zip(r["beta"], off)):
        c = cmap(0.5 + 0.5 * o / span)
        a.plot(r["time"], 1e3 * r["slide"][:, w], "-", color=c, label=f"β = {np.rad2deg(be):.2f}° ({o:+g}°)")
        a.plot(r["time"], 1e3 * r["predicted"][:, w], ":", color=c)
    a.set_xlabel("time [s]"), a.set_ylabel("slide down the slope [mm]")
    a.set_title("Slope test (dotted: ½ g (sin β − μk cos β) t²)"), a.legend(fontsize=7), a.grid(alpha=0.3)
    s = r["summary"]
    b.plot(np.rad2deg(r["beta"]), 1e3 * r["slide"][-1], "o-", label="simulated")
    b.plot(np.rad2deg(r["beta"]), 1e3 * r["predicted"][-1], "k:", label="Coulomb prediction")
    b.axvline(s["friction_angle_deg"], color="r", ls="--", label=f"atan(μs) = {s['friction_angle_deg']:.2f}°")
    b.set_yscale("symlog", linthresh=0.1)
    b.set_xlabel("incline β [deg]"), b.set_ylabel(f"slide after {s['duration_s']:.2f} s [mm]")
    b.set_title("Stick / slip transition"), b.legend(fontsize=8), b.grid(alpha=0.3)
    return _save(fig, path)


def plot_force_plate(r: dict, path) -> Path:
    plt = _plt()
    fig, ax = plt.subplots(figsize=(8, 5))
    for w, g in enumerate(r["gaits"]):
        lab = g + (" (unstable)" if r["unstable"][w] else "")
        ax.plot(r["time"], 1e3 * r["pull"][:, w], color=GAIT_COLORS.get(g), label=lab + ": along +x")
        if "force_magnitude" in r:
            ax.plot(r["time"], 1e3 * r["force_magnitude"][:, w], color=GAIT_COLORS.get(g), ls="--", lw=1,
                    label=lab + ": |F|")
    ax.axhline(0.0, color="k", lw=0.5)
    ax.set_xlabel("time [s]"), ax.set_ylabel("anchor force [mN]")
    how = "the EPM's pass repeated in place" if r["summary"].get("rewind") else "the EPM advancing"
    ax.set_title(f"Force plate: tail tied to a fixed point (the worm's pull on the anchor; {how})", fontsize=10)
    ax.legend(fontsize=8, ncol=3, loc="upper center", bbox_to_anchor=(0.5, -0.13)), ax.grid(alpha=0.3)
    return _save(fig, path)


def plot_strain(r: dict, path) -> Path:
    plt = _plt()
    from matplotlib.collections import LineCollection  # optional dependency: matplotlib (the plots extra)
    from matplotlib.colors import LinearSegmentedColormap, Normalize  # optional: matplotlib

    cmap = LinearSegmentedColormap.from_list("blue_red", ["#1f3fff", "#ff1f1f"])
    W = len(r["gaits"])
    fig, axes = plt.subplots(W + 1, 1, figsize=(9, 2.3 * (W + 1)))
    vmax = max(1e-12, float(r["max_abs"].max()))
    norm = Normalize(0.0, vmax)
    e = r["edges"]
    for w, g in enumerate(r["gaits"]):
        ax = axes[w]
        x = 1e3 * r["peak_positions"][w]
        order = np.argsort(r["max_abs"][w])  # most strained bars drawn last (on top)
        segs = np.stack([x[e[order, 0]][:, [0, 2]], x[e[order, 1]][:, [0, 2]]], axis=1)
        lc = LineCollection(segs, colors=cmap(norm(r["max_abs"][w][order])), linewidths=2)
        ax.add_collection(lc)
        ax.set_xlim(segs[..., 0].min() - 3, segs[..., 0].max() + 3)
        ax.set_ylim(segs[..., 1].min() - 3, segs[..., 1].max() + 3)
        ax.set_aspect("equal", adjustable="datalim")
        ax.set_title(f"{g}: max |strain| per bar over the run (side view at the most strained instant); "
                     f"max {r['max_abs'][w].max():.2e}", fontsize=9)
        ax.set_xlabel("x [mm]"), ax.set_ylabel("z [mm]")
    sm = plt.cm.ScalarMappable(norm=norm, cmap=cmap)
    fig.colorbar(sm, ax=list(axes[:W]), label="max |Cauchy strain|")
    ax = axes[W]
    for w, g in enumerate(r["gaits"]):
        ax.plot(r["time"], r["max_over_bars"][:, w], color=GAIT_COLORS.get(g), label=g)
    ax.set_xlabel("time [s]"), ax.set_ylabel("max |strain| over bars"), ax.set_yscale("log")
    ax.legend(fontsize=8), ax.grid(alpha=0.3)
    return _save(fig, path)


def plot_deformation(r: dict, path) -> Path:
    plt = _plt()
    W = len(r["gaits"])
    fig, axes = plt.subplots(W, 2, figsize=(11, 2.6 * W), squeeze=False)
    names = ["blue-pink", "pink-white", "white-green", "green-red"]
    for w, g in enumerate(r["gaits"]):
        a, b = axes[w]
        for i in range(4):
            a.plot(r["time"], r["ratio"][:, w, i], label=f"{names[i]} (seg{i}-seg{i + 1})")
        a.axhline(1.0, color="k", lw=0.5)
        a.set_ylabel("deformation ratio"), a.set_title(f"{g}" + (" (unstable)" if r["unstable"][w] else ""))
        a.grid(alpha=0.3)
        b.plot(r["time"], 1e3 * r["displacement"][:, w], color=GAIT_COLORS.get(g))
        b.set_ylabel("displacement [mm]"), b.set_title(f"{g}: net {1e3 * r['displacement'][-1, w]:+.2f} mm")
        b.grid(alpha=0.3)
    axes[0, 0].legend(fontsize=7, ncol=2)
    axes[-1, 0].set_xlabel("time [s]"), axes[-1, 1].set_xlabel("time [s]")
    fig.tight_layout()
    return _save(fig, path)


def plot_fit(r: dict, path) -> Path:
    """k_α calibration (:func:`warpworm.analysis.material_fit.fit_hinge_stiffness`): measured vs fitted curve, and the RMS
    residual of every candidate of the coarse and fine batches."""
    plt = _plt()
    fig, (a, b) = plt.subplots(1, 2, figsize=(11, 4.2))
    s = r["summary"]
    xl = "shortening [mm]" if r["test"] == "compression" else "centre deflection [mm]"
    a.plot(1e3 * r["displacement"], 1e3 * r["force"], "ko", mfc="none", label="measured (table)")
    a.plot(1e3 * r["displacement"], 1e3 * r["fitted_force"], "r-",
           label=f"simulated, k_α = {r['hinge_stiffness']:.4g} N/rad")
    a.set_xlabel(xl), a.set_ylabel("force [mN]")
    a.set_title(f"{r['test']} fit: RMS residual {1e3 * r['rms_residual_n']:.3g} mN "
                f"({100 * r['relative_residual']:.2f} %)")
    a.legend(fontsize=8), a.grid(alpha=0.3)
    b.plot(r["coarse"]["k"], 1e3 * r["coarse"]["rms"], "o-", ms=3, label="coarse batch")
    b.plot(r["fine"]["k"], 1e3 * r["fine"]["rms"], "s-", ms=3, label="fine batch")
    b.axvline(r["hinge_stiffness"], color="r", ls="--", label="fit")
    b.set_xscale("log"), b.set_yscale("log")
    b.set_xlabel("k_α [N/rad]"), b.set_ylabel("RMS residual [mN]")
    b.set_title(f"one world per candidate ({s['coarse_worlds']} + {s['fine_worlds']})")
    b.legend(fontsize=8), b.grid(alpha=0.3, which="both")
    return _save(fig, path)


PLOTS = {
    "force-distance": plot_force_distance, "compression": plot_compression, "flexure": plot_flexure,
    "slope": plot_slope, "force-plate": plot_force_plate, "strain": plot_strain, "deformation": plot_deformation,
}
