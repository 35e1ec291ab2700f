"""The report's figures as PNG (matplotlib, Agg): cusp height per slice (thesis Fig. 14), chordal error per face,
regularity histograms."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from amprep.geometry.measure.cusp import BoxCusp  # noqa: E402
from amprep.geometry.measure.regularity import BIN_EDGES, MEASURES  # noqa: E402
from amprep.geometry.measure.report import FaceScore


def cusp_per_slice(box: BoxCusp, approximate_mean: float, path: Path) -> Path:
    """Each box's cusp height at its slice height (points) and the per-slice maximum (line)."""
    fig, ax = plt.subplots(figsize=(8, 4.5), dpi=110)
    filled = np.isfinite(box.height)
    z = box.slice_heights[box.slice_index[filled]]
    ax.scatter(z, box.height[filled], s=4, c="tab:red", alpha=0.35, linewidths=0, label="box cusp height")
    n = len(box.slice_heights)
    top = np.full(n, np.nan)
    if filled.any():
        tmp = np.full(n, -np.inf)
        np.maximum.at(tmp, box.slice_index[filled], box.height[filled])
        top = np.where(np.isfinite(tmp), tmp, np.nan)
    ax.plot(box.slice_heights, top, c="black", lw=1, label="slice maximum")
    ax.axhline(approximate_mean, c="tab:blue", ls="--", lw=1, label=f"approximate mean {approximate_mean:.4g} mm")
    ax.set_xlabel("slice height along the build direction (mm)")
    ax.set_ylabel("cusp height (mm)")
    ax.set_title("Cusp height per slice (bounding-box method)")
    ax.legend(loc="upper right", fontsize=8)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    return path


def chordal_per_face(faces: list[FaceScore], tolerance: float | None, path: Path) -> Path:
    """Mean and max chordal error of every CAD face with a measured error, by face id."""
    rows = [(f.id, f.chordal_error) for f in faces if f.chordal_error is not None]
    fig, ax = plt.subplots(figsize=(max(6, min(20, len(rows) * 0.05 + 6)), 4.5), dpi=110)
    ids = np.array([i for i, _ in rows])
    ax.bar(ids, [c.max for _, c in rows], width=0.9, color="tab:orange", label="max")
    ax.bar(ids, [c.mean for _, c in rows], width=0.9, color="tab:blue", label="mean")
    if tolerance:
        ax.axhline(tolerance, c="black", ls="--", lw=1, label=f"tolerance {tolerance:g} mm")
    ax.set_xlabel("CAD face id")
    ax.set_ylabel("chordal error (mm)")
    ax.set_title("Chordal error per face")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    return path


def regularity_histograms(q: dict[str, np.ndarray], path: Path) -> Path:
    """Per measure: a fine histogram and the source table's four bins."""
    fig, axes = plt.subplots(1, 3, figsize=(12, 3.8), dpi=110, sharey=True)
    for ax, name in zip(axes, MEASURES):
        ax.hist(q[name], bins=50, range=(0, 1), color="tab:gray")
        counts = np.histogram(q[name], bins=np.r_[BIN_EDGES, 1.0 + 1e-12])[0]
        for lo, hi, c in zip(BIN_EDGES, np.r_[BIN_EDGES[1:], 1.0], counts):
            ax.axvline(lo, c="tab:red", lw=0.6)
            ax.text((lo + hi) / 2, 0.95, f"{c}", transform=ax.get_xaxis_transform(), ha="center", fontsize=8)
        ax.set_title(f"{name}: mean {np.mean(q[name]):.3f}")
        ax.set_xlabel("regularity")
    axes[0].set_ylabel("triangles")
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    return path


def error_vs_size(comparison: dict[str, Any], path: Path) -> Path:
    """Mean chordal error of the refined faces against binary STL size: uniform re-tessellations as a curve, the
    input, SMA and VTA as points (the thesis's comparison, Tables 1, 2, 6)."""
    fig, ax = plt.subplots(figsize=(7, 4.5), dpi=110)

    def xy(rows: list[dict[str, Any]]) -> tuple[list[float], list[float]]:
        ok = [r for r in rows if r.get("chordal_error")]
        return [r["file_size"] / 1024 for r in ok], [r["chordal_error"]["mean"] for r in ok]

    x, y = xy(comparison.get("uniform", []))
    ax.plot(x, y, "o-", c="tab:gray", ms=4, label="uniform re-tessellation")
    seen: set[int] = set()
    for r, tol in zip([q for q in comparison.get("uniform", []) if q.get("chordal_error")], x):
        if r["triangles"] in seen:  # coarse tolerances that give the same mesh (angular deflection governs)
            continue
        seen.add(r["triangles"])
        ax.annotate(f"{r['tolerance']:.3g}", (tol, r["chordal_error"]["mean"]), fontsize=6, xytext=(3, 3),
                    textcoords="offset points")
    for key, style in (("before", ("s", "black")), ("refined", ("*", "tab:red")), ("other_method", ("D", "tab:blue"))):
        row = comparison.get(key)
        if row and row.get("chordal_error"):
            ax.plot(row["file_size"] / 1024, row["chordal_error"]["mean"], style[0], c=style[1], ms=9, label=row["label"])
    ys = np.concatenate([np.asarray(line.get_ydata(), float).ravel() for line in ax.get_lines()] or [np.zeros(0)])
    if (ys > 0).any():  # nothing over the faces to refine (all errors 0, or none): a linear axis, not a crash
        ax.set_xscale("log")
        ax.set_yscale("log")
    ax.set_xlabel("binary STL size (KiB)")
    ax.set_ylabel("mean chordal error of the refined faces (mm)")
    ax.set_title("Error against file size")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    return path
