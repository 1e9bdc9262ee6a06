"""``epa rpg CASE_DIR``: rpg_trajectory_evaluation's ``analyze_trajectory_single.py`` on rpg's folder layout.

Reads ``stamped_groundtruth.txt``, ``stamped_traj_estimate.txt`` (``--mul_trials N``:
``stamped_traj_estimate0.txt`` .. ``N-1``; other ``--est_types`` use rpg's other names), ``eval_cfg.yaml``
(``align_type``, ``align_num_frames``; without it rpg's defaults ``sim3`` / ``-1``) and the optional
``start_end_time.yaml`` (``start_time_sec``, ``end_time_sec``), and writes rpg's files under
``CASE_DIR/saved_results/<est_type>/``:

* ``stamped_est_gt_matches<i>.txt`` (estimate index, groundtruth index; ``%d``),
* ``absolute_err_statistics_<align_type>_<n><_#i>.yaml`` (``trans``, ``rot``, ``scale``),
* ``relative_error_statistics_<d:3.1f with '_'><_#i>.yaml`` (``trans``, ``trans_perc``, ``yaw``, ``rot``,
  ``gravity``, ``rot_deg_per_m``),
* with more than one trial: ``mt_abs_err_<align>.yaml``, ``mt_rmse_{trans,rot,scale}_all_<align>.txt``,
  ``mt_rel_err_<d>.yaml``, ``mt_rel_err_overall.yaml`` and ``mt_success_indices.txt``.

``<_#i>`` is ``_#0``, ``_#1``, ... with more than one trial and empty otherwise. The YAML files are written
the way rpg writes them (``yaml.dump(..., default_flow_style=False)``, keys sorted) and, as rpg does, an
existing file is read and only its labels are replaced. Quirks of the file handling kept from rpg:

* two distances with the same one-decimal name (``{:3.1f}``) share one file; the later distance wins;
* a trial whose estimate file is missing or has no matched pose is skipped (not in
  ``mt_success_indices.txt``); the first successful trial fixes the distances for the later ones;
* ``--mul_trials 1`` (or 0) is a single run: no ``_#0`` suffix and no ``mt_`` files;
* the matches file holds every match, before the ``start_end_time.yaml`` window is applied (the window
  compares the *groundtruth* stamp of each match, inclusive at both ends).

Differences from rpg, all deliberate: errors are always recomputed (rpg reuses an existing matches file and
its pickled relative errors unless ``--recalculate_errors``; no pickles are read or written here), no plots
are drawn (rpg's plotting options are accepted and ignored), and bad input (a missing groundtruth, a
missing single estimate, unreadable YAML or text, an impossible ``align_num_frames``, fewer than 2 matched
poses) stops with one :class:`EpaError` line naming the file instead of rpg's assertion or silence.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from epa.core.errors import EpaError
from epa.metrics.rpg import MT_ABS, dist_str, multi_trial_statistics, rel_labels, yaml_text
from epa.readers.rpg_files import read_eval_cfg, read_yaml
from epa.rpg import protocol as P

GT_NAME = "stamped_groundtruth.txt"
EST_NAMES = {
    "traj_est": "stamped_traj_estimate",
    "pose_graph": "stamped_pose_graph_estimate",
    "ba_estimate": "stamped_ba_estimate",
}
MATCH_NAMES = {
    "traj_est": "stamped_est_gt_matches",
    "pose_graph": "stamped_pg_gt_matches",
    "ba_estimate": "stamped_ba_gt_matches",
}


def read_stamped(path: Path) -> np.ndarray:
    """A ``# time x y z qx qy qz qw`` file (whitespace separated, ``#`` comments) as an (N, >=8) array."""
    path = Path(path)
    try:
        text = path.read_text()
    except OSError as exc:
        raise EpaError(f"cannot read: {exc.strerror or exc}", path=path) from None
    rows, width = [], None
    for no, line in enumerate(text.splitlines(), 1):
        fields = line.split("#", 1)[0].split()
        if not fields:
            continue
        if width is None:
            width = len(fields)
            if width < 8:
                raise EpaError(
                    f"{width} columns, expected 8 (time x y z qx qy qz qw)", path=path, line=no
                )
        elif len(fields) != width:
            raise EpaError(
                f"{len(fields)} columns where the first row has {width}", path=path, line=no
            )
        try:
            rows.append([float(x) for x in fields])
        except ValueError:
            raise EpaError("not a number in this row", path=path, line=no) from None
    if not rows:
        raise EpaError("no poses", path=path)
    return np.array(rows, dtype=float)


def read_start_end(case_dir: Path) -> tuple[float, float]:
    """``start_end_time.yaml``'s window (seconds, inclusive); unbounded when the file or a key is absent."""
    path = Path(case_dir) / "start_end_time.yaml"
    start, end = -math.inf, math.inf
    if path.exists():
        d = read_yaml(path)
        if not isinstance(d, dict):
            raise EpaError("expected a mapping with start_time_sec and/or end_time_sec", path=path)
        try:
            start = float(d.get("start_time_sec", start))
            end = float(d.get("end_time_sec", end))
        except (TypeError, ValueError):
            raise EpaError("start_time_sec and end_time_sec must be numbers", path=path) from None
    return start, end


def evaluate(
    gt: np.ndarray,
    est: np.ndarray,
    align_type: str,
    align_num_frames: int,
    start: float = -math.inf,
    end: float = math.inf,
    distances=None,
    est_path=None,
) -> dict:
    """One trial as rpg's ``Trajectory`` computes it: matches, alignment, absolute and relative errors.

    ``distances`` None: rpg's 10..50 % of the groundtruth length. Returns a dict with ``matches`` (all),
    ``n_matched``, ``scale``/``rot``/``trans`` (the alignment), ``distances``, ``abs`` (per-pose errors),
    ``abs_stats`` (trans, rot, scale), ``rel`` {distance: metric vectors and ``<metric>_stats``}."""
    matches = P.associate(est[:, 0], gt[:, 0], 0.0, P.MAX_DIFF)
    kept = [(i, j) for i, j in matches if not (gt[j, 0] < start or gt[j, 0] > end)]
    out = {"matches": matches, "n_matched": len(kept)}
    if not kept:
        return out
    if len(kept) < 2:
        raise EpaError(
            "only 1 pose matches the groundtruth within 0.02 s; at least 2 are needed",
            path=est_path,
        )
    ie, ig = np.array(kept).T
    p_es, q_es, p_gt, q_gt = est[ie, 1:4], est[ie, 4:8], gt[ig, 1:4], gt[ig, 4:8]
    raw = gt[~((gt[:, 0] < start) | (gt[:, 0] > end))]
    traj_length = P.path_length(raw[:, 1:4])
    try:
        s, r, t = P.align(p_es, p_gt, q_es, q_gt, align_type, align_num_frames)
    except ValueError as exc:
        raise EpaError(str(exc), path=est_path) from None
    p_al, q_al = P.apply_alignment(s, r, t, p_es, q_es)
    out.update(
        scale=s,
        rot=r,
        trans=t,
        traj_length=traj_length,
        p_es_aligned=p_al,
        **P.errors(p_es, q_es, p_gt, q_gt, s, p_al, q_al, traj_length, distances),
    )
    return out


def update_and_save(path: Path, labels: dict) -> None:
    """rpg's ``update_and_save_stats``: merge labels into the YAML file (kept keys stay), sorted dump."""
    stats = {}
    if path.exists():
        stats = read_yaml(path)
        if not isinstance(stats, dict):
            raise EpaError(
                "an existing statistics file rpg would update is not a mapping", path=path
            )
    stats.update(labels)
    path.write_text(yaml_text(stats))


def _savetxt_column(path: Path, values, fmt: str) -> None:
    path.write_text("".join(fmt % v + "\n" for v in values))


def run_case(case_dir, est_type: str = "traj_est", mul_trials: int | None = None) -> dict:
    """Evaluate one rpg folder for one estimate type and write rpg's files. Returns ``trials``
    {index: evaluate() result}, ``success`` and ``skipped`` (indices), ``mt`` (multi-trial statistics or
    None) and
    ``written`` (paths)."""
    case = Path(case_dir)
    if not case.is_dir():
        raise EpaError("not a folder", path=case)
    if est_type not in EST_NAMES:
        raise EpaError(f"unknown estimate type {est_type!r} (one of {', '.join(EST_NAMES)})")
    if mul_trials is not None and mul_trials < 0:
        raise EpaError("--mul_trials must not be negative")
    n_trials = mul_trials or 1
    gt_path = case / GT_NAME
    if not gt_path.exists():
        raise EpaError("groundtruth file missing", path=gt_path)
    align_type, n_frames = read_eval_cfg(case)
    start, end = read_start_end(case)
    gt = read_stamped(gt_path)
    align_str = f"{align_type}_{n_frames}"
    save = case / "saved_results" / est_type
    save.mkdir(parents=True, exist_ok=True)
    written, trials, success, distances = [], {}, [], None
    for i in range(n_trials):
        suffix = "" if n_trials == 1 else str(i)
        tag = "" if suffix == "" else "_#" + suffix
        est_path = case / f"{EST_NAMES[est_type]}{suffix}.txt"
        if not est_path.exists():
            if n_trials == 1:
                raise EpaError("estimate file missing", path=est_path)
            continue
        res = evaluate(
            gt, read_stamped(est_path), align_type, n_frames, start, end, distances, est_path
        )
        match_path = save / f"{MATCH_NAMES[est_type]}{suffix}.txt"
        _savetxt_column(match_path, res["matches"], "%d %d")
        written.append(match_path)
        if res["n_matched"] == 0:
            if n_trials == 1:
                raise EpaError(
                    "no pose matches the groundtruth within 0.02 s (and the time window)",
                    path=est_path,
                )
            continue
        trials[i] = res
        success.append(i)
        if distances is None:
            distances = res["distances"]
        abs_path = save / f"absolute_err_statistics_{align_str}{tag}.yaml"
        update_and_save(abs_path, res["abs_stats"])
        written.append(abs_path)
        for d, e in res["rel"].items():
            rel_path = save / f"relative_error_statistics_{dist_str(d)}{tag}.yaml"
            update_and_save(rel_path, rel_labels(e))
            written.append(rel_path)
    if not success:
        raise EpaError(
            f"none of the {n_trials} estimates {EST_NAMES[est_type]}0..{n_trials - 1}.txt could be "
            "evaluated (missing or no matched pose)",
            path=case,
        )
    mt = None
    if n_trials > 1:
        mt = multi_trial_statistics([trials[i] for i in success])
        written += write_multi_trial(save, align_str, mt, success)
    return {
        "trials": trials,
        "success": success,
        "skipped": [i for i in range(n_trials) if i not in trials],
        "mt": mt,
        "written": list(dict.fromkeys(written)),
        "align_str": align_str,
        "save_dir": save,
    }


def write_multi_trial(save: Path, align_str: str, mt: dict, success: list[int]) -> list[Path]:
    """rpg's ``MulTrajError.saveErrors``."""
    written = []
    abs_path = save / f"mt_abs_err_{align_str}.yaml"
    update_and_save(abs_path, {lab: mt["abs_stats"][et] for et, lab in MT_ABS})
    written.append(abs_path)
    for et, _ in MT_ABS:
        p = save / f"mt_{et}_all_{align_str}.txt"
        _savetxt_column(p, mt["rmse"][et], "%.18e")
        written.append(p)
    for d, st in mt["rel_stats"].items():
        p = save / f"mt_rel_err_{dist_str(d)}.yaml"
        update_and_save(p, {lab: st[m] for m, lab in zip(P.REL_METRICS, P.REL_LABELS)})
        written.append(p)
    p = save / "mt_rel_err_overall.yaml"
    update_and_save(p, {lab: mt["overall"][m] for m, lab in zip(P.REL_METRICS, P.REL_LABELS)})
    written.append(p)
    p = save / "mt_success_indices.txt"
    _savetxt_column(p, success, "%i")
    written.append(p)
    return written


def add_parser(sub) -> None:
    """``epa rpg``: rpg's ``analyze_trajectory_single.py`` command line (plot options accepted, ignored)."""
    r = sub.add_parser(
        "rpg", help="rpg_trajectory_evaluation's analyze_trajectory_single.py on an rpg folder"
    )
    r.add_argument(
        "result_dir", help="folder with stamped_groundtruth.txt, the estimate(s), eval_cfg.yaml"
    )
    r.add_argument(
        "--mul_trials",
        type=int,
        default=None,
        help="number of trials: stamped_traj_estimate0..N-1.txt (default: one, no index)",
    )
    r.add_argument(
        "--est_types",
        nargs="*",
        default=["traj_est"],
        choices=list(EST_NAMES),
        help="estimate types (default: traj_est)",
    )
    r.add_argument(
        "--recalculate_errors",
        action="store_true",
        help="accepted for rpg's command line; errors are always recomputed",
    )
    for flag in ("--png", "--plot_scale_traj", "--plot", "--no_plot"):
        r.add_argument(
            flag, action="store_true", help="accepted for rpg's command line; no plots are drawn"
        )
    r.add_argument(
        "--plots_dir", default="", help="accepted for rpg's command line; no plots are drawn"
    )
    r.add_argument("--mul_plot_idx", type=int, nargs="*", default=[0], help="accepted, ignored")


def run(args) -> None:
    """Run ``epa rpg`` for parsed arguments; prints one line per estimate type."""
    for est_type in args.est_types:
        res = run_case(args.result_dir, est_type, args.mul_trials)
        first = res["trials"][res["success"][0]]["abs_stats"]["trans"]["rmse"]
        print(
            f"epa rpg: {est_type} {res['align_str']}: {len(res['success'])} trial(s) evaluated "
            f"(first: translation RMSE {first:.6f} m); wrote {len(res['written'])} files to {res['save_dir']}"
        )
        if res["skipped"]:
            print(
                f"epa rpg: {est_type}: trials {res['skipped']} skipped (estimate missing or no matched pose)"
            )
