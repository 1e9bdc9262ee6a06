"""The grid figures drawn per dataset, from the report stage's per-case files (never from the stage
artifacts, so 10,000 cases stay cheap):

- ``trajectories_<dataset>``: the reference and, per algorithm, its median-ATE run, each aligned as
  its case was evaluated (the align stage's estimate, from the case's ``bundles/trajectory.json``),
  top view to scale over a side view, start and end marked;
- ``relative_error_<dataset>``: the relative error per segment length as boxes per algorithm,
  translation (m) and rotation (deg; yaw in mode rpg), every run's segments pooled as
  rpg_trajectory_evaluation pools its trials; the lengths are those the dataset's cases were
  evaluated at.

The report stage writes each case's relative errors to ``10_report/grid_samples.json``
(:func:`case_samples`): per segment length the number of segments and at most
:data:`MAX_ORDER_STATISTICS` of their sorted values, evenly spread in rank (all of them when there
are no more), about 13 kB a case.
"""

from __future__ import annotations

import csv
import functools
import json
from pathlib import Path

import numpy as np

from epa.artifacts import files
from epa.artifacts.stage import folder
from epa.core.errors import EpaError
from epa.outputs import figures

PREFIXES = ("trajectories", "relative_error")
SAMPLES_FILE = "grid_samples.json"
SAMPLES_FORMAT = "epica-grid-samples/1"
# order statistics kept per case and segment length: a quartile from them is within 1 % of the
# case's segments in rank (exact where a case has no more segments)
MAX_ORDER_STATISTICS = 101
OVERLAY_POINTS = 500  # per line of an overlay: enough at 7 in wide, for the picture only
WHISKER = 1.5  # whiskers at the farthest segment within 1.5 IQR of the box, as matplotlib's


def names(datasets) -> list[str]:
    """The per-dataset figures' names, in the order they are written."""
    return [f"{prefix}_{d}" for d in sorted(datasets) for prefix in PREFIXES]


# ----------------------------------------------------------------------------- per case
def order_statistics(values, most: int = MAX_ORDER_STATISTICS) -> tuple[int, np.ndarray]:
    """The number of finite ``values`` and at most ``most`` of them, sorted, evenly spread in rank
    (the smallest and the largest kept)."""
    v = np.sort(np.asarray(values, float)[np.isfinite(values)])
    return len(v), v[figures.thin(len(v), most)]


def case_samples(case) -> dict:
    """A case's ``grid_samples.json`` document from its metrics stage's per-segment errors: mode
    rpg's relative errors (translation, yaw) where its metric wrote them, else the distance RPE's
    (translation, rotation angle)."""
    if case.has("metrics", "rpg_relative_errors.csv"):
        t = files.read_csv(case.path("metrics", "rpg_relative_errors.csv"))
        source, length, rot, rot_label = "rpg", "distance_m", "yaw_deg", "yaw"
    else:
        t = files.read_csv(case.path("metrics", "rpe_segments.csv"))
        source, length, rot, rot_label = "rpe", "length_m", "rot_deg", "rotation"
    lengths = sorted({float(x) for x in t.get(length, [])})
    out: dict = {"lengths": lengths, "n": [], "trans_m": [], "rot_deg": []}
    for L in lengths:
        at = t[length] == L
        n_t, q_t = order_statistics(t["trans_m"][at])
        n_r, q_r = order_statistics(t[rot][at])
        out["n"].append([n_t, n_r])
        out["trans_m"].append(q_t)
        out["rot_deg"].append(q_r)
    return {"format": SAMPLES_FORMAT, "source": source, "rotation": rot_label, "relative": out}


def _read_samples(path: Path) -> dict | None:
    """A case's samples, or None where the report stage wrote none (it failed)."""
    try:
        doc = json.loads(path.read_bytes())
    except FileNotFoundError:
        return None
    except (OSError, ValueError) as exc:
        raise EpaError(f"not a grid samples file: {exc}", path=str(path)) from None
    if not isinstance(doc, dict) or doc.get("format") != SAMPLES_FORMAT:
        raise EpaError(f"not a grid samples file (format {SAMPLES_FORMAT})", path=str(path))
    return doc


# ----------------------------------------------------------------------------- box statistics
def box_stats(parts) -> dict | None:
    """Box-plot statistics of segments pooled over runs, from each run's order statistics.

    Parameters
    ----------
    parts : list of (int, array)
        Per run: its number of segments and their order statistics (:func:`order_statistics`).

    Returns
    -------
    dict or None
        ``med``, ``q1``, ``q3``, ``whislo``, ``whishi``, ``n`` (segments), ``runs``; None without a
        segment. The quartiles are numpy's (linear) percentiles of the pooled segments, the whiskers
        matplotlib's (the farthest segment within 1.5 IQR of the box): exactly where every segment
        is stored. Otherwise a run's segments between two stored ones are taken as evenly spread
        in value between them (each stored value keeps its rank).
    """
    runs = [(n, q) for n, q in ((int(n), np.asarray(q, float)) for n, q in parts) if n and len(q)]
    if not runs:
        return None
    pooled = [q for n, q in runs if len(q) == n]
    thinned = [(n, q) for n, q in runs if len(q) != n]
    if thinned:
        # one np.interp for every thinned run, each run's ranks shifted past the previous run's:
        # ranks are integers (exact in float64) and each run's first and last are stored, so every
        # value is the one a call per run gives, bit for bit, at a fraction of the calls' overhead
        start = np.cumsum([0] + [n for n, _ in thinned[:-1]])
        grids = [_ranks(n, len(q)) for n, q in thinned]
        pooled.append(
            np.interp(
                np.concatenate([every + s for (every, _), s in zip(grids, start)]),
                np.concatenate([stored + s for (_, stored), s in zip(grids, start)]),
                np.concatenate([q for _, q in thinned]),
            )
        )
    x = np.concatenate(pooled)  # the quartiles and whiskers below do not depend on the order
    q1, med, q3 = (float(v) for v in np.percentile(x, [25, 50, 75]))
    iqr = q3 - q1
    lo = x[x >= q1 - WHISKER * iqr]
    hi = x[x <= q3 + WHISKER * iqr]
    return {
        "med": med,
        "q1": q1,
        "q3": q3,
        "whislo": min(float(lo.min()), q1) if lo.size else q1,
        "whishi": max(float(hi.max()), q3) if hi.size else q3,
        "n": len(x),
        "runs": len(runs),
    }


@functools.lru_cache(maxsize=1024)
def _ranks(n: int, kept: int) -> tuple[np.ndarray, np.ndarray]:
    """Every rank of ``n`` segments and the ranks of the ``kept`` stored (:func:`order_statistics`):
    the same few pairs recur over a grid's runs, and making them was a third of reading a dataset."""
    every, stored = np.arange(n), figures.thin(n, kept)
    every.flags.writeable = stored.flags.writeable = False
    return every, stored


# ----------------------------------------------------------------------------- grid bundles
def _number(row: dict, key: str) -> float:
    """A summary.csv row's number (nan where empty)."""
    try:
        return float(row[key])
    except (KeyError, ValueError):
        return np.nan


def median_run(rows: list[dict]) -> dict | None:
    """The run whose ATE RMSE is the median of the cell's (the lower of the two middle ones for an
    even number; ties by run name); None without a finite ATE."""
    runs = sorted(
        (r for r in rows if np.isfinite(_number(r, "ate_trans_rmse_m"))),
        key=lambda r: (_number(r, "ate_trans_rmse_m"), r["run"]),
    )
    return runs[(len(runs) - 1) // 2] if runs else None


def _thin_rows(rows, most: int) -> np.ndarray:
    """At most ``most`` of a bundle's points, evenly spread (first and last kept): for the picture."""
    a = np.array(rows, dtype=float)  # a null (None) is nan
    return a[figures.thin(len(a), most)]


def _report_folder(results_dir: Path, row: dict) -> Path:
    return results_dir / "cases" / row["algorithm"] / row["dataset"] / row["run"] / folder("report")


def cells_by_dataset(rows: list[dict], has_result) -> list[tuple[str, list]]:
    """Per dataset (sorted): per algorithm of the grid (sorted; its place is its colour, as in the
    other grid figures) ``(place, algorithm, its summary.csv rows with a result)``."""
    algs = sorted({r["algorithm"] for r in rows})
    datasets = sorted({r["dataset"] for r in rows})
    cells: dict[tuple[str, str], list[dict]] = {}
    for r in rows:
        if has_result(r["status"]):
            cells.setdefault((r["dataset"], r["algorithm"]), []).append(r)
    return [(d, [(k, a, cells.get((d, a), [])) for k, a in enumerate(algs)]) for d in datasets]


def dataset_bundles(results_dir, dataset: str, here) -> dict[str, dict]:
    """A dataset's two bundles, from its cells (:func:`cells_by_dataset`) and the per-case files."""
    results_dir = Path(results_dir)
    return {
        f"trajectories_{dataset}": _overlay_bundle(results_dir, dataset, here),
        f"relative_error_{dataset}": _boxes_bundle(results_dir, dataset, here),
    }


def grid_bundles(results_dir, rows: list[dict], has_result) -> dict[str, dict]:
    """Every per-dataset figure's bundle, from summary.csv's ``rows`` (``has_result(status)``: a case
    with numbers) and the per-case files of the report stage."""
    out = {}
    for d, here in cells_by_dataset(rows, has_result):
        out.update(dataset_bundles(results_dir, d, here))
    return out


def draw_dataset(results_dir, dataset: str, here, style: str = "wide") -> list[Path]:
    """A dataset's figures and their bundles (``results/figures/``): one job of the figures rule."""
    results_dir = Path(results_dir)
    written = []
    for name, b in dataset_bundles(results_dir, dataset, here).items():
        figures.write_bundle(results_dir / "figures" / "bundles" / f"{name}.json", b)
        written += figures.render(b, results_dir / "figures" / name, style=style)
    return written


def _overlay_bundle(results_dir: Path, dataset: str, here) -> dict:
    lines, ref, ref_n = [], None, -1
    for k, a, runs in here:
        row = median_run(runs)
        if row is None:
            continue
        path = _report_folder(results_dir, row) / "bundles" / "trajectory.json"
        if not path.is_file():  # its report stage failed: nothing to draw from
            continue
        d = figures.read_bundle(path)["data"]
        est = _thin_rows(d["est"], OVERLAY_POINTS)
        lines.append({"label": a, "run": row["run"], "color": k, "xyz": est})
        n = np.nan_to_num(_number(row, "n_matched"), nan=0.0)
        if n > ref_n:  # the reference over the most matched poses of the runs drawn
            ref, ref_n = _thin_rows(d["ref"], OVERLAY_POINTS), n
    return figures.bundle(
        "overlay",
        f"Trajectories on {dataset}: each algorithm's median-ATE run, aligned as evaluated",
        {
            "dataset": dataset,
            "ref": ref if ref is not None else [],
            "lines": lines,
            "colors": figures.OKABE_ITO,
        },
    )


def _boxes_bundle(results_dir: Path, dataset: str, here) -> dict:
    per_alg: dict[int, dict[float, dict[str, list]]] = {}
    rotation = set()
    for k, _, runs in here:
        for row in runs:
            doc = _read_samples(_report_folder(results_dir, row) / SAMPLES_FILE)
            if doc is None:
                continue
            rotation.add(doc.get("rotation", "rotation"))
            rel = doc["relative"]
            for j, L in enumerate(rel["lengths"]):
                cell = per_alg.setdefault(k, {}).setdefault(float(L), {"trans": [], "rot": []})
                cell["trans"].append((rel["n"][j][0], rel["trans_m"][j]))
                cell["rot"].append((rel["n"][j][1], rel["rot_deg"][j]))
    lengths = sorted({L for cells in per_alg.values() for L in cells})
    algorithms = [
        {
            "label": a,
            "color": k,
            "trans": [box_stats(per_alg.get(k, {}).get(L, {}).get("trans", [])) for L in lengths],
            "rot": [box_stats(per_alg.get(k, {}).get(L, {}).get("rot", [])) for L in lengths],
        }
        for k, a, _ in here
        if k in per_alg
    ]
    # cases evaluated differently (mode rpg's yaw beside an angle) would share an axis: say both
    rot_label = " / ".join(sorted(rotation)) or "rotation"
    return figures.bundle(
        "boxes",
        f"Relative error per segment length on {dataset} (every run's segments pooled)",
        {
            "dataset": dataset,
            "lengths": lengths,
            "algorithms": algorithms,
            "ylabels": ["translation error [m]", f"{rot_label} error [deg]"],
            "colors": figures.OKABE_ITO,
        },
    )


def read_summary(summary_csv) -> list[dict]:
    with open(summary_csv, encoding="utf-8", newline="") as fh:
        return list(csv.DictReader(fh))
