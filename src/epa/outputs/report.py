"""Per-case report (``10_report/``) and grid figures, built from the stage artifacts only: nothing is
recomputed here but plot coordinates (the first-pose overlay of the "before" view).

Per case: ``metrics.json`` (every stage's record in one document), ``metrics_summary.csv``
(section, metric, value), ``report_en.md`` / ``report_zh.md``, ``figures/<name>.png|pdf`` with each
figure's bundle in ``bundles/<name>.json``, and ``<run>.zip`` (every artifact plus a manifest).
"""

from __future__ import annotations

import csv
import hashlib
import io as _io
import json
import re
import zipfile
from pathlib import Path

import numpy as np

from epa.artifacts import files
from epa.artifacts.case import CaseData
from epa.metrics.accuracy import segment_key
from epa.outputs import case_report, dataset_figures, figures, parallel, tables

CASE_FIGURES = ("trajectory", "ape_time", "rpe_box", "xcorr", "steps", "sigma3")
GRID_FIGURES = ("ate", "success_rate", "success_curve", "drift_rate", "rmse_time")
# The order the grid figures are drawn in by several workers: the costliest first, so that no
# worker starts a long one last (PNG + PDF on the 52 EuRoC cases: rmse_time 0.56 s, success_curve
# 0.50, ate 0.46, drift_rate 0.27, success_rate 0.16; write_grid_figures with two workers 1.43-1.57 s
# in GRID_FIGURES' order, 1.23-1.42 s in this one). The bytes do not depend on it.
DRAW_ORDER = ("rmse_time", "success_curve", "ate", "drift_rate", "success_rate")


# ----------------------------------------------------------------------------- case artifacts
# ----------------------------------------------------------------------------- case bundles
def time_zero(data: CaseData) -> float:
    """The zero of a case's time axes (figures, the reports' fail segments): the stamp of the first
    matched reference pose."""
    return float(data.matched[0].t[0])


def case_bundles(data: CaseData, doc: dict | None = None) -> dict[str, dict]:
    """Every per-case figure's bundle, from a case's artifacts (``doc``: its document, where it
    has been read: :meth:`CaseData.document`)."""
    p = data.folder.path
    ref, aligned, ape, fail = data.matched[0], data.aligned, data.ape, data.fail_segments
    drift = doc["drift"] if doc and "drift" in doc else files.read_json(p("drift", "drift.json"))
    sync = files.read_json(p("sync", "sync.json"))
    t0 = time_zero(data)
    k = figures.thin(len(ref))
    out = {
        "trajectory": figures.bundle(
            "trajectory",
            "Reference and aligned estimate, coloured by APE",
            {"ref": ref.p[k], "est": aligned.p[k], "err": ape["trans_m"][k]},
        )
    }
    out["ape_time"] = figures.bundle(
        "ape_time",
        "APE over time, fail segments shaded",
        {
            "t": ape["t"][k] - t0,
            "ape": ape["trans_m"][k],
            "fail_start": np.asarray(fail.get("t_start", []), float) - t0,
            "fail_end": np.asarray(fail.get("t_end", []), float) - t0,
            "threshold": (drift.get("knee") or {}).get("threshold_m"),
        },
    )
    seg = files.read_csv(p("metrics", "rpe_segments.csv"))
    lengths = sorted({float(x) for x in seg["length_m"]}) if len(seg.get("length_m", [])) else []
    out["rpe_box"] = figures.bundle(
        "rpe_box",
        "RPE per segment length",
        {"lengths": lengths, "trans": [seg["trans_m"][seg["length_m"] == L] for L in lengths]},
    )
    xc = files.read_csv(p("sync", "xcorr.csv"))
    step1 = sync.get("step1", {})
    out["xcorr"] = figures.bundle(
        "xcorr",
        "Step 1: angular-speed cross-correlation",
        {
            "lag": xc.get("lag_s", []),
            "corr": xc.get("corr", []),
            "peak": step1.get("estimated") if step1.get("used") else None,
            "reason": step1.get("reason", ""),
        },
    )
    est_m = data.matched[1]  # the estimate as read, at the matched poses
    # "before": the estimate as read, put on the reference by its first pose only
    r0 = ref.r[0] @ est_m.r[0].T
    before = (est_m.p - est_m.p[0]) @ r0.T + ref.p[0]
    out["steps"] = figures.bundle(
        "steps",
        "Before and after Steps 1-3 (top view)",
        {"ref": ref.p[k], "before": before[k], "after": aligned.p[k]},
    )
    n = data.nees
    if n:
        kk = figures.thin(len(n["t"]))  # drawn as a band: 1000 samples suffice
        out["sigma3"] = figures.bundle(
            "sigma3",
            "Per-axis error and its ±3σ bound",
            {
                "t": n["t"][kk] - n["t"][0],
                **{c: n[c][kk] for c in n if c.startswith(("err_", "sigma_"))},
            },
        )
    return out


# ----------------------------------------------------------------------------- documents
def _numbers(prefix: str, obj, out: list) -> list:
    """(dotted name, value) of every number in a nested record, appended to ``out`` in order."""
    if isinstance(obj, dict):
        for k, v in obj.items():
            _numbers(f"{prefix}.{k}" if prefix else str(k), v, out)
    elif isinstance(obj, (int, float)) and not isinstance(obj, bool):
        out.append((prefix, obj))
    return out


SETTINGS_AND_MATRICES = ("load", "sync", "calibrate", "alignment", "thresholds", "rpe")


def summary_rows(doc: dict) -> list[tuple[str, str, float]]:
    """(section, metric, value) for every number in the document, except matrices and settings."""
    return [
        (section, name, value)
        for section, record in doc.items()
        for name, value in _numbers(
            "", {k: v for k, v in record.items() if k not in SETTINGS_AND_MATRICES}, []
        )
    ]


# fields csv.writer writes as they are (no quotes): what the names of a record are
_PLAIN_FIELDS = re.compile(r"[\w.+-]*", re.ASCII)


def summary_csv(doc: dict) -> str:
    """metrics_summary.csv: csv.writer's text, joined here where no name needs quotes (a
    csv.writer call a row was most of the file's cost)."""
    rows = summary_rows(doc)
    values = [f"{v:.9g}" if isinstance(v, float) else str(v) for _, _, v in rows]
    names = [f"{section},{metric}" for section, metric, _ in rows]
    if all(s and m for s, m, _ in rows) and _PLAIN_FIELDS.fullmatch(
        ".".join(names).replace(",", ".")
    ):
        return "".join(["section,metric,value\n", *(f"{n},{v}\n" for n, v in zip(names, values))])
    buf = _io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(["section", "metric", "value"])
    w.writerows([(s, m, v) for (s, m, _), v in zip(rows, values)])
    return buf.getvalue()


def flags(doc: dict) -> list[str]:
    """Why a reader would open this case: what drift detection and Steps 1-2 found, and the registered
    metrics' warnings (empty: nothing)."""
    m, drift = doc.get("metrics", {}), doc.get("drift", {})
    out = []
    if drift.get("global_failed"):
        out.append("globally failed")
    elif drift.get("n_fail_segments"):
        out.append(f"{drift['n_fail_segments']} fail segments")
    if (m.get("calibrate", {}).get("plan") or {}).get("fallback"):
        out.append("evaluated the ov_eval way (" + m["calibrate"].get("reason", "") + ")")
    return out + case_report.metric_warnings(doc)


def failed(doc: dict) -> bool:
    """Whether the case failed or hides a failure: drift detection failed it (globally, or on
    segments) or a registered metric warned (the Sim3 scale check). These are the cases
    ``report.figures: flagged`` draws. A Step 1-2 fallback is flagged in the text, not drawn: it is a
    routine outcome (21 of the 52 real EuRoC cases), whose numbers are the standard ones, and drawing
    them made the reports half of that grid's work (docs/performance.md)."""
    drift = doc.get("drift", {})
    return bool(
        drift.get("global_failed")
        or drift.get("n_fail_segments")
        or case_report.metric_warnings(doc)
    )


def case_zip(case_root: Path, out: Path) -> None:
    """Every artifact of the case and a manifest (file, bytes, sha256), for sharing one evaluation."""
    files = sorted(
        p
        for p in case_root.rglob("*")
        if p.is_file() and p != out and not p.name.startswith(".") and p.suffix != ".zip"
    )
    manifest = []
    tmp = out.with_name("." + out.name + ".tmp")
    with zipfile.ZipFile(tmp, "w", compression=zipfile.ZIP_DEFLATED) as z:
        for f in files:
            data = f.read_bytes()
            rel = f.relative_to(case_root).as_posix()
            z.writestr(rel, data)
            manifest.append(
                {"file": rel, "bytes": len(data), "sha256": hashlib.sha256(data).hexdigest()}
            )
        z.writestr(
            "MANIFEST.json",
            json.dumps({"format": "epica-case-bundle/1", "files": manifest}, indent=1),
        )
    tmp.replace(out)


def _grid_provenance(case_root: Path) -> str:
    """Where the run's provenance.json is, relative to the case's report: a grid case's is
    results/provenance.json (written by the tables rule), an `epa eval` case's is beside it."""
    if (case_root / "provenance.json").exists():
        return "../provenance.json"
    return "../../../../../provenance.json"


def write_case_report(data: CaseData, name: str, cfg: dict) -> dict:
    """The report stage: documents, plot bundles, figures (``report.figures``: flagged cases, all
    or none) and the zip, from the case's artifacts (``data`` reads them)."""
    c = cfg["report"]
    case = data.folder
    folder = case.path("report", "report.json").parent
    doc, text = case.document_text(type(data).DOCUMENT)  # write_json's text of doc
    files.write_text(folder / "metrics.json", text)
    files.write_text(folder / "metrics_summary.csv", summary_csv(doc))
    # Figures cost most of a report (0.7 s a case): by default only the cases a reader opens first,
    # those drift detection failed, are drawn; every case keeps its bundles.
    with files.tables_once():  # both read 06_metrics/rpe_segments.csv
        bundles = case_bundles(data, doc)
        # what the grid's per-dataset figures read of this case (its relative errors, thinned)
        samples = dataset_figures.case_samples(case)
    memo: dict = {}  # the steps bundle repeats the trajectory bundle's arrays
    for fig_name, b in bundles.items():
        figures.write_bundle(folder / "bundles" / f"{fig_name}.json", b, memo)
    figures.write_bundle(folder / dataset_figures.SAMPLES_FILE, samples)
    why = flags(doc)
    draw = c["figures"] == "all" or (c["figures"] == "flagged" and failed(doc))
    drawn = list(bundles) if draw else []
    for fig_name in drawn:  # from the bundle as written: `epa fig` redraws the same bytes
        formats = ("png", "pdf") if c["pdf"] else ("png",)
        bundle = figures.read_bundle(folder / "bundles" / f"{fig_name}.json")
        figures.render(bundle, folder / "figures" / fig_name, formats=formats)
    inputs = case_report.case_inputs(case.root, case.record("load", "load.json"), cfg)
    for lang in ("en", "zh"):
        md = case_report.report_md(
            doc,
            name,
            drawn,
            lang,
            data.fail_segments,
            t0=time_zero(data),
            bundles=bundles,
            every_figure=CASE_FIGURES,
            cfg_report=c,
            inputs=inputs,
            grid_provenance=_grid_provenance(case.root),
        )
        files.write_text(folder / f"report_{lang}.md", md)
    if c["rerun"]:
        from epa.outputs import recording

        recording.write_rrd(data, name, folder / f"{name.replace('/', '_')}.rrd")
    if c["zip"]:  # last: it holds the other report files
        case_zip(case.root, folder / f"{name.replace('/', '_')}.zip")
    return {"figures": drawn, "flags": why, "zip": bool(c["zip"]), "rerun": bool(c["rerun"])}


# ----------------------------------------------------------------------------- grid figures
def _nanmean(values):
    """np.nanmean, without numpy's "Mean of empty slice" warning when every value is nan (an
    algorithm whose every run failed): nan, drawn as a gap."""
    a = np.asarray(values, float)
    return np.nanmean(a) if (~np.isnan(a)).any() else np.nan


def _column(row: dict, key: str) -> float:
    """A summary.csv row's number (nan where empty)."""
    try:
        return float(row[key])
    except (KeyError, ValueError):
        return np.nan


def grid_bundles(summary_csv_path, consistency_dir, segments) -> dict[str, dict]:
    """ATE per algorithm and dataset, drift rate against segment length, success rate, RMSE over
    time across runs, success against the drift threshold: from summary.csv, success_curves.csv and
    results/consistency/, one colour per algorithm."""
    with open(summary_csv_path, encoding="utf-8", newline="") as fh:
        rows = list(csv.DictReader(fh))
    ok = [r for r in rows if tables.has_result(r["status"])]
    algs = sorted({r["algorithm"] for r in rows})
    datasets = sorted({r["dataset"] for r in rows})
    runs = _grouped(ok, "algorithm", "dataset")

    def cells(key):
        """Per algorithm, per dataset: the runs' finite values of a summary.csv column."""
        return [
            [
                [v for v in (_column(r, key) for r in runs.get((a, d), ())) if np.isfinite(v)]
                for d in datasets
            ]
            for a in algs
        ]

    success = [
        [[np.nanmean(v)] if v else [] for v in a] for a in cells("success_rate_distance_pct")
    ]
    ate = {"values": cells("ate_trans_rmse_m"), "ylabel": "ATE RMSE [m]", "log": True}
    rate = {"bars": True, "values": success, "ylabel": "success rate [% of path]"}
    return {
        "ate": figures.bundle(
            "grouped",
            "ATE per algorithm and dataset (runs)",
            {"datasets": datasets, "algorithms": algs, **ate, "colors": figures.OKABE_ITO},
        ),
        "success_rate": figures.bundle(
            "grouped",
            "Success rate per algorithm and dataset",
            {"datasets": datasets, "algorithms": algs, **rate, "colors": figures.OKABE_ITO},
        ),
        "drift_rate": _drift_rate_bundle(ok, algs, segments),
        "rmse_time": _rmse_time_bundle(Path(consistency_dir), algs, datasets),
        "success_curve": _success_curve_bundle(
            Path(summary_csv_path).parent / "success_curves.csv", algs, datasets
        ),
    }


def _grouped(rows: list[dict], *columns: str) -> dict[tuple, list[dict]]:
    """CSV rows grouped by the values of ``columns``, in their order: scanning every row for each
    algorithm and dataset made the grid figures quadratic (13.9 s on 10,000 cases)."""
    out: dict[tuple, list[dict]] = {}
    for r in rows:
        out.setdefault(tuple(r[c] for c in columns), []).append(r)
    return out


def _drift_rate_bundle(ok: list[dict], algs: list[str], segments) -> dict:
    lines = []
    of_alg = _grouped(ok, "algorithm")
    for k, a in enumerate(algs):
        ys = [
            _nanmean(
                [_column(r, f"drift_rate_{segment_key(s)}m_pct") for r in of_alg.get((a,), ())]
                or [np.nan]
            )
            for s in segments
        ]
        lines.append({"label": a, "x": list(segments), "y": ys, "color": k})
    return figures.bundle(
        "lines",
        "Distance drift rate against segment length",
        {
            "panels": [{"lines": lines}],
            "xlabel": "segment length [m]",
            "ylabel": "drift rate [%]",
            "markers": True,
            "colors": figures.OKABE_ITO,
            "log": True,  # a diverged run would flatten the others
        },
    )


def _rmse_time_bundle(consistency_dir: Path, algs: list[str], datasets: list[str]) -> dict:
    panels = []
    for d in datasets:
        panel_lines = []
        for k, a in enumerate(algs):
            path = consistency_dir / a / f"{d}.csv"
            if path.exists():
                t = files.read_csv(path)
                if len(t.get("t", [])):
                    kk = figures.thin(len(t["t"]), 1500)
                    x, y = t["t"][kk] - t["t"][0], t["rmse_pos_m"][kk]
                    panel_lines.append({"label": a, "x": x, "y": y, "color": k})
        panels.append({"title": d, "lines": panel_lines})
    return figures.bundle(
        "lines",
        "RMSE over time across runs",
        {
            "panels": panels,
            "xlabel": "time [s]",
            "ylabel": "RMSE [m]",
            "colors": figures.OKABE_ITO,
            "log": True,
        },
    )


def _success_curve_bundle(curves_path: Path, algs: list[str], datasets: list[str]) -> dict:
    with open(curves_path, encoding="utf-8", newline="") as fh:
        curves = _grouped(list(csv.DictReader(fh)), "algorithm", "dataset")
    panels = []
    for d in datasets:
        panel_lines = []
        for k, a in enumerate(algs):
            rows = curves.get((a, d))
            if rows:
                x = [_column(r, "factor") for r in rows]
                y = [_column(r, "success_rate_distance_pct") for r in rows]
                panel_lines.append({"label": a, "x": x, "y": y, "color": k})
        panels.append({"title": d, "lines": panel_lines})
    return figures.bundle(
        "lines",
        "Success rate against the drift threshold",
        {
            "panels": panels,
            "xlabel": "threshold / default",
            "ylabel": "success rate [% of path]",
            "colors": figures.OKABE_ITO,
            "logx": True,
            "sharey": True,
            "dashes": True,
            "ylim": [0, 102],
        },
    )


def write_grid_figures(
    results_dir, segments, style: str = "wide", workers: int = 1, per_dataset: bool = True
) -> list[Path]:
    """The grid figures and their bundles; with ``per_dataset`` (the per-case reports were
    written: ``report.per_case``) also each dataset's trajectories and relative-error boxes
    (:mod:`epa.outputs.dataset_figures`). ``workers`` > 1 draws them in that many forked processes:
    the figures rule is the run's serial tail, and drawing (PDF font subsetting most of all) is most
    of its time; a dataset's job also reads its cases' files. Each figure is drawn from its bundle
    alone, so the bytes do not depend on it."""
    results_dir = Path(results_dir)
    jobs: list[tuple] = []
    for name, b in grid_bundles(
        results_dir / "summary.csv", results_dir / "consistency", segments
    ).items():
        figures.write_bundle(results_dir / "figures" / "bundles" / f"{name}.json", b)
        jobs.append(("draw", b, results_dir / "figures" / name, style))
    rank = {name: k for k, name in enumerate(DRAW_ORDER)}
    order = sorted(range(len(jobs)), key=lambda k: rank.get(jobs[k][2].name, len(rank)))
    if per_dataset:
        rows = dataset_figures.read_summary(results_dir / "summary.csv")
        cells = dataset_figures.cells_by_dataset(rows, tables.has_result)
        # a dataset's two figures cost more than any one of the others: first
        order = list(range(len(jobs), len(jobs) + len(cells))) + order
        jobs += [("dataset", results_dir, d, here, style) for d, here in cells]
    if workers > 1:
        figures.prepare(style)  # matplotlib imported once, before the fork
    drawn = dict(zip(order, parallel.map_forked(_grid_job, [jobs[k] for k in order], workers)))
    return [path for k in range(len(jobs)) for path in drawn[k]]  # in the bundles' order


def _grid_job(what: str, *args) -> list[Path]:
    """One job of :func:`write_grid_figures`: draw a bundle, or a dataset's figures."""
    if what == "draw":
        b, stem, style = args
        return figures.render(b, stem, style=style)
    return dataset_figures.draw_dataset(*args)
