"""evo's result zip: what ``epa ape|rpe --save_results X.zip`` writes and what ``epa res`` reads.

The layout is evo 1.38.1's ``file_interface.save_res_file``: ``info.json`` (title, ref_name,
est_name, label), ``stats.json`` (rmse, mean, median, std, min, max, sse), one ``NAME.npy`` per
array (error_array; with stamps also seconds_from_start, timestamps, distances_from_start and
distances; alignment_transformation_sim3 when aligned) and the trajectories the errors were computed
on, ``NAME.tum`` (stamped) or ``NAME.kitti``, named by their source as evo names them (the file as
given, or the bag topic). evo writes the trajectories only with its setting ``save_traj_in_zip``;
epica always does. ``evo_res`` reads these zips; :func:`read` reads evo's and epica's.
"""

from __future__ import annotations

import io
import json
import math
import zipfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from epa.core import geometry
from epa.core.errors import EpaError
from epa.core.trajectory import Trajectory

STAT_ORDER = ("rmse", "mean", "median", "std", "min", "max", "sse")  # evo's StatisticsType order
# a fixed entry date: the same result gives the same bytes (evo stamps the time of writing)
ENTRY_DATE = (1980, 1, 1, 0, 0, 0)


def info(result, *, ref_name: str, est_name: str) -> dict:
    """evo's info.json: title, ref_name, est_name, label ("APE (m)")."""
    return {
        "title": result.title,
        "ref_name": ref_name,
        "est_name": est_name,
        "label": f"{result.kind.upper()} ({result.unit})",
    }


def poses(result) -> tuple[Trajectory, Trajectory]:
    """The reference and estimate as evo keeps them in its result: every matched pose (APE), or the
    first pose and each pair's end (RPE: evo's ``[0] + delta_ids``)."""
    ref, est = result.ref, result.est
    if ref is None or est is None:
        raise ValueError("the result holds no trajectories")
    if result.ends is None:
        return ref, est
    keep = np.concatenate([[0], result.ends]).astype(int)
    return ref.select(keep), est.select(keep)


def arrays(result) -> dict[str, np.ndarray]:
    """evo's np_arrays, in its order. For an RPE the time and distance arrays are those of each
    pair's end (evo drops the first kept pose, which ends no pair)."""
    out = {"error_array": np.asarray(result.errors, float)}
    if result.timed:
        ref, est = poses(result)
        skip = 0 if result.ends is None else 1
        out["seconds_from_start"] = (est.t - est.t[0])[skip:]
        out["timestamps"] = np.asarray(est.t, float)[skip:]
        out["distances_from_start"] = geometry.path_distances(ref.p)[skip:]
        out["distances"] = geometry.path_distances(est.p)[skip:]
    if result.sim3 is not None:
        out["alignment_transformation_sim3"] = result.sim3
    return out


def _tum_text(traj: Trajectory) -> str:
    buf = io.StringIO()  # evo's write_tum_trajectory_file: np.savetxt's default %.18e
    np.savetxt(buf, np.column_stack([traj.t, traj.p, traj.q]), delimiter=" ")
    return buf.getvalue()


def _kitti_text(traj: Trajectory) -> str:
    rows = np.concatenate([traj.r_as_printed, traj.p[:, :, None]], axis=2).reshape(len(traj), 12)
    buf = io.StringIO()  # evo's write_kitti_poses_file: the first 3 rows of each 4x4 pose
    np.savetxt(buf, rows, delimiter=" ")
    return buf.getvalue()


def to_bytes(result, *, ref_name: str, est_name: str) -> bytes:
    """The zip as evo's save_res_file writes it (stored, not deflated, as evo's)."""
    entries: list[tuple[str, bytes]] = [
        ("info.json", json.dumps(info(result, ref_name=ref_name, est_name=est_name)).encode()),
        ("stats.json", json.dumps({k: float(result.stats[k]) for k in STAT_ORDER}).encode()),
    ]
    for name, array in arrays(result).items():
        buf = io.BytesIO()
        np.save(buf, array)
        entries.append((f"{name}.npy", buf.getvalue()))
    ref, est = poses(result)
    text, suffix = (_tum_text, ".tum") if result.timed else (_kitti_text, ".kitti")
    # a dict as evo's: one trajectory when both sides have the same name
    for name, traj in {ref_name: ref, est_name: est}.items():
        entries.append((name + suffix, text(traj).encode("utf-8")))
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w") as z:
        for name, data in entries:
            entry = zipfile.ZipInfo(name, date_time=ENTRY_DATE)
            entry.external_attr = 0o600 << 16  # as writestr gives an entry named by a string
            z.writestr(entry, data)
    return buf.getvalue()


def write(path, result, *, ref_name: str, est_name: str) -> None:
    from epa.artifacts import files

    files.write_bytes(path, to_bytes(result, ref_name=ref_name, est_name=est_name))


# ----------------------------------------------------------------------------- reading
@dataclass
class EvoZip:
    path: str
    info: dict
    stats: dict

    @property
    def title(self) -> str:
        return self.info["title"]

    def label(self, use_filenames: bool = False) -> str:
        """evo_res's column label: the file as given, or the base name of est_name."""
        if use_filenames:
            return self.path
        name = self.info.get("est_name")
        return Path(name).name if isinstance(name, str) else "unnamed_result"


def is_evo_zip(z: zipfile.ZipFile) -> bool:
    return {"info.json", "stats.json"} <= set(z.namelist())


def read(z: zipfile.ZipFile, where: str) -> EvoZip:
    """An evo result zip's info and statistics, checked: a title, and every statistic a finite
    number."""
    try:
        doc_info = json.loads(z.read("info.json"))
        doc_stats = json.loads(z.read("stats.json"))
    except (ValueError, UnicodeDecodeError) as exc:
        raise EpaError(f"an evo result zip with unreadable JSON: {exc}", path=where) from None
    if not isinstance(doc_info, dict) or not isinstance(doc_info.get("title"), str):
        raise EpaError("evo result zip: info.json holds no title (key 'title')", path=where)
    if not isinstance(doc_stats, dict) or not doc_stats:
        raise EpaError("evo result zip: stats.json holds no statistics", path=where)
    for name, v in doc_stats.items():
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            raise EpaError(
                f"evo result zip: stats.json key {name!r} is not a finite number: {v!r}",
                path=where,
            )
    return EvoZip(where, doc_info, doc_stats)


def evo_res_text(results: list[EvoZip], *, use_filenames: bool = False) -> str:
    """What evo_res prints for these zips: the first title, then the statistics of each (one row,
    labelled as evo_res labels it), as evo_res builds and prints its table with pandas."""
    import pandas as pd

    labels = [r.label(use_filenames) for r in results]
    twice = sorted({x for x in labels if labels.count(x) > 1})
    if twice:
        raise EpaError(
            f"results must have different est_name values (repeated: {', '.join(twice)}); "
            "--use_filenames labels them by file"
        )
    frames = [
        pd.DataFrame(data={"info": r.info, "stats": r.stats}).T.stack().dropna().to_frame(name=x)
        for r, x in zip(results, labels)
    ]
    df = pd.concat(frames, axis="columns")
    with pd.option_context("display.width", 80, "display.max_colwidth", 20):
        table = df.loc["stats"].T.to_string(line_width=80)
    return f"\n{results[0].title}\n\n\n{table}\n\n"
