"""Figures and markdown tables of the paper's experiment (:mod:`.paper`,
``appearance-nav reproduce``): Figs. 2-3 (reduce-reconstruct and tangent images), Tables 1-2
beside the paper's numbers, and the JSON encoder of the report."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

__all__ = ["FEATURE_NAMES", "PAPER_TABLE1", "PAPER_TABLE2", "figures", "jsonable",
           "tables_markdown"]

#: The seed paper's Table I (intrinsic dimension of its 2500 images) and Table II (RRMSE).
PAPER_TABLE1 = {"perspective": (1, 11, 3), "fisheye": (1, 7, 3), "catadioptric": (1, 11, 3)}
PAPER_TABLE2 = {"perspective": (0.045, 0.063), "fisheye": (0.037, 0.059),
                "catadioptric": (0.039, 0.058)}
FEATURE_NAMES = {"pixel_pca": "PixelPCA", "pixel_pca_masked": "PixelPCA, near ground masked",
                 "efficientnet": "EfficientNet-Lite0 (ImageNet), block 10 pyramid",
                 "efficientnet_global": "EfficientNet-Lite0 (ImageNet), global pool of the head",
                 "small_cnn": "SmallCNN (other cities)"}


def jsonable(obj: Any) -> Any:
    """``json.dumps`` default: numpy scalars and arrays."""
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    raise TypeError(f"not JSON-serialisable: {type(obj).__name__}")


def _rel(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.linalg.norm(a - b) / np.linalg.norm(b))


def figures(inputs: dict[str, tuple[Any, Any, np.ndarray, np.ndarray]], out: Path
            ) -> dict[str, Any]:
    """Figs. 2-3 of the paper for every camera: a test image, its PCA reconstruction, its
    GSE reduced (to q numbers) and reconstructed version ``PCA^-1(g_u(r*(w)))``, and the
    tangent image ``PCA^-1``-linear part of ``G_u`` (a signed image: how the picture
    changes per unit of the representation, i.e. as the robot moves along the route).

    ``inputs[camera] = (PixelPCA fitted on the training images, the fitted GSERegressor,
    all images, test indices)``. Returns the relative Frobenius errors per camera."""
    if not inputs:
        return {}
    stats: dict[str, Any] = {}
    fig, axes = plt.subplots(len(inputs), 4, figsize=(10, 2.7 * len(inputs)), squeeze=False)
    for row, (camera, (pca_features, gse, images, te)) in enumerate(inputs.items()):
        i = int(te[len(te) // 3])
        x = images[i:i + 1]
        shape = x.shape[1:]
        orig = x[0].astype(np.float64) / 255.0
        w = pca_features.transform(x)
        pca = pca_features.pca_
        rec_pca = pca.inverse_transform(w).reshape(shape)
        rec_gse = pca.inverse_transform(gse.reconstruct(w)).reshape(shape)
        tangent = (gse.feature_tangents(w)[0, :, 0] @ pca.components_).reshape(shape)
        stats[camera] = {"image_index": i, "pca_rel_error": _rel(rec_pca, orig),
                         "gse_rel_error": _rel(rec_gse, orig),
                         "gse_vs_pca_rel": _rel(rec_gse, rec_pca),
                         "q": int(gse.embedding_.shape[1])}
        t = tangent.mean(axis=2)
        lim = float(np.abs(t).max()) or 1.0
        panels = [(orig, "original"),
                  (np.clip(rec_pca, 0, 1), f"PCA-{pca.n_components_} ({_rel(rec_pca, orig):.3f})"),
                  (np.clip(rec_gse, 0, 1), (f"GSE q={stats[camera]['q']} "
                                           f"({_rel(rec_gse, orig):.3f})"))]
        for ax, (img, title) in zip(axes[row], panels):
            ax.imshow(img)
            ax.set_title(title, fontsize=8)
        axes[row, 3].imshow(t, cmap="RdBu_r", vmin=-lim, vmax=lim)
        axes[row, 3].set_title("tangent image", fontsize=8)
        axes[row, 0].set_ylabel(camera, fontsize=9)
        for ax in axes[row]:
            ax.set_xticks([])
            ax.set_yticks([])
    fig.suptitle("reduce-reconstruct (relative Frobenius error) and tangent images, "
                 "out-of-sample route images", fontsize=9)
    fig.tight_layout()
    fig.savefig(out / "reconstruction_tangent.png", dpi=110)
    plt.close(fig)
    return stats


def _fmt(v: float | None, digits: int = 4) -> str:
    if v is None:
        return "-"
    return "failed" if not np.isfinite(v) else f"{v:.{digits}f}"


def _best_bold(values: list[float | None]) -> list[str]:
    """The values formatted, the smallest finite one in bold (the best RRMSE of a row)."""
    finite = [v for v in values if v is not None and np.isfinite(v)]
    best = min(finite) if finite else None
    return [f"**{_fmt(v)}**" if v is not None and v == best else _fmt(v) for v in values]


def _rows(report: dict[str, Any], dataset: str) -> dict[tuple[str, str], dict[str, Any]]:
    rows: dict[tuple[str, str], dict[str, Any]] = {}
    for r in report["table2"]:
        if r["dataset"] == dataset:
            rows.setdefault((r["camera"], r["features"]), {})[r["method"]] = r
    return rows


def _readings(values: list[Any], count_ones: bool = True) -> str:
    """"a, b, c (1 in k/n)" of rounded readings (the count only with ``count_ones``: the
    route, whose reading by design is 1)."""
    out = ", ".join(f"{v:.0f}" for v in values)
    if not count_ones or len(values) < 2:
        return out
    return out + f" (1 in {sum(v == 1 for v in values)}/{len(values)})"


def _table1_row(label: str, t: dict[str, Any], paper: tuple[Any, ...], route: bool = True
                ) -> str:
    seeds = t.get("global_seeds") or [t["global"]]
    slopes = t.get("global_values")
    slope = f" [{min(slopes):.2f}-{max(slopes):.2f}]" if slopes else ""
    iso = t.get("isomap_seeds")
    no_cut = t.get("global_no_cut")
    iso_cell = "-" if iso is None else _readings(iso, route)
    return (f"| {label} | {_readings(seeds, route)}{slope} | {iso_cell} | "
            f"{'-' if no_cut is None else f'{no_cut:.0f}'} | "
            f"{t['local']:.1f} | {t['pointwise']:.1f} | "
            + ("-" if paper[0] == "-" else f"{paper[0]} / {paper[1]} / {paper[2]}") + " |")


def tables_markdown(report: dict[str, Any]) -> str:
    """Table 1, Table 2 (route, position only) and the random 3-DoF table, with the
    paper's numbers beside ours."""
    a = report["args"]
    lines = [(f"# Section V reproduced: city {a['scene_seed']}, {a['image_size']}x"
             f"{a['image_size']} images, n = {a['n']} per data set, 70/30 random split "
             f"(seed {a['split_seed']})"), "",
             ("## Table 1: intrinsic dimension of the route images (raw pixels; the random 3-DoF "
              "images below)"), "",
             ("| camera | global (geodesic corr. dim.; every seed [slopes]) | Isomap, loop cut "
              "| Isomap, no cut | local (corr. dim.) | pointwise (MLE) | paper (global / local / "
              "pointwise) |"),
             "|---|---:|---:|---:|---:|---:|---|"]
    for cam, t in report["table1"].items():
        lines.append(_table1_row(cam, t, PAPER_TABLE1.get(cam, ("-",) * 3)))
    for cam, t in (report.get("table1_random") or {}).items():
        lines.append(_table1_row(f"{cam}, random 3-DoF poses", t, ("-",) * 3, route=False))
    rrmse = "RRMSE = sqrt(sum |theta_hat - theta|^2 / sum |theta - mean theta|^2) over (x, y)"
    lines += ["", "## Table 2: localization along the route (position only), " + rrmse, "",
              ("| camera | features | GSE | GSE, verified | KNR | kNN | GSE / KNR | "
              "verified / KNR | GSE median error (m) | KNR median error (m) | paper GSE | "
              "paper KNR |"),
              "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for (cam, feat), m in _rows(report, "route").items():
        g, v, k, n = (m.get(x) for x in ("gse", "gse_verified", "knr", "knn"))
        p = PAPER_TABLE2.get(cam, (None, None))
        ratios = [a["rrmse"] / k["rrmse"] if a and k else None for a in (g, v)]
        cells = _best_bold([x["rrmse"] if x else None for x in (g, v, k, n)])
        lines.append(f"| {cam} | {FEATURE_NAMES.get(feat, feat)} | {' | '.join(cells)} | "
                     f"{_fmt(ratios[0], 2)} | {_fmt(ratios[1], 2)} | "
                     f"{_fmt(g and g['median_m'], 3)} | "
                     f"{_fmt(k and k['median_m'], 3)} | {_fmt(p[0], 3)} | {_fmt(p[1], 3)} |")
    rand = _rows(report, "random")
    if rand:
        lines += ["", ("## Random 3-DoF poses over the whole city (position RRMSE, heading RMSE "
                  "in rad)"), "",
                  ("| camera | features | GSE | KNR | kNN | GSE heading | KNR heading | "
                  "kNN heading | KNR median error (m) |"),
                  "|---|---|---:|---:|---:|---:|---:|---:|---:|"]
        for (cam, feat), m in rand.items():
            g, k, n = (m.get(x) for x in ("gse", "knr", "knn"))
            lines.append(
                f"| {cam} | {FEATURE_NAMES.get(feat, feat)} | {_fmt(g and g['rrmse'], 3)} | "
                f"{_fmt(k and k['rrmse'], 3)} | {_fmt(n and n['rrmse'], 3)} | "
                f"{_fmt(g and g['heading_rmse'], 2)} | {_fmt(k and k['heading_rmse'], 2)} | "
                f"{_fmt(n and n['heading_rmse'], 2)} | {_fmt(k and k['median_m'], 2)} |")
    figs = report.get("figures") or {}
    if figs:
        lines += ["", ("## Figs. 2-3: reduce-reconstruct and tangent images "
                  "(`reconstruction_tangent.png`)"), "",
                  ("| camera | PCA reconstruction error | GSE reduced (q numbers) and "
                  "reconstructed error | GSE vs PCA reconstruction |"), "|---|---:|---:|---:|"]
        for cam, s in figs.items():
            lines.append(f"| {cam} | {s['pca_rel_error']:.3f} | {s['gse_rel_error']:.3f} "
                         f"(q={s['q']}) | {s['gse_vs_pca_rel']:.3f} |")
    lines += ["", f"Total time {report['timing']['total'] / 60:.1f} min."]
    return "\n".join(lines) + "\n"
