"""A *source* (a text file or a bag topic) read with the settings that apply to it.

A source's settings are the ``load`` section's, overridden by ``sources.reference`` /
``sources.datasets.<dataset>`` for a reference and ``sources.algorithms.<algorithm>`` for an
estimate. They travel with each case (the load rule's params), so changing one source's settings
re-runs only its cases.
"""

from __future__ import annotations

import logging
from pathlib import Path

from epa.core import geometry
from epa.core.errors import EpaError
from epa.core.trajectory import Trajectory
from epa.readers import text
from epa.readers.detect import is_bag

log = logging.getLogger(__name__)
KEYS = (
    "format",
    "topic",
    "frames",
    "static_topic",
    "stamp",
    "time_unit",
    "unsorted",
    "kitti_rate",
    "timing",
    "orientation_covariance",
    "metric_scale",  # an estimate's declaration, read by metrics.sim3_check (never by a reader)
)
TIMING_DEFAULTS = ("{run}_timing.txt", "{run}_timing.csv")


def options(
    cfg: dict, side: str, *, algorithm: str | None = None, dataset: str | None = None
) -> dict:
    """The settings of one source: ``side`` is ``reference`` or ``estimate``."""
    load = cfg["load"]
    opts = {
        "format": load["truth_format" if side == "reference" else "estimate_format"],
        "topic": None,
        "frames": None,
        "static_topic": "/tf_static",
        "stamp": load["stamp"],
        "time_unit": load["time_unit"],
        "unsorted": load["unsorted"],
        "kitti_rate": load["kitti_rate"],
        "timing": None,
        "orientation_covariance": "local",
    }
    src = cfg.get("sources") or {}
    layers = (
        [src.get("reference") or {}, (src.get("datasets") or {}).get(dataset) or {}]
        if side == "reference"
        else [(src.get("algorithms") or {}).get(algorithm) or {}]
    )
    for layer in layers:
        opts.update({k: v for k, v in layer.items() if v is not None})
    return opts


def timing_file(run_path, opts: dict) -> Path | None:
    """A run's per-frame timing file: ``opts["timing"]`` (``{run}`` = the run's name, relative to
    its folder; an error when missing) or the naming rule ``<run>_timing.txt|csv`` (None when absent)."""
    run_path = Path(run_path)
    name = run_path.name if run_path.is_dir() else run_path.stem
    if opts.get("timing"):
        path = run_path.parent / opts["timing"].replace("{run}", name)
        if not path.is_file():
            raise EpaError(
                f"timing file not found (sources timing: {opts['timing']})", path=str(path)
            )
        return path
    for pattern in TIMING_DEFAULTS:
        path = run_path.parent / pattern.replace("{run}", name)
        if path.is_file():
            return path
    return None


def read_printed_quaternions(
    path, opts: dict, *, c_parser_min_bytes: int = text.C_PARSER_MIN_BYTES
) -> Trajectory | None:
    """A text source read again with its settings, its quaternions as the file prints them (not
    normalised), for the ETH3D protocol (its program rotates by them). None where a source prints no
    quaternions: a bag (its messages' quaternions are normalised on reading), a KITTI file (rotation
    blocks) or positions only. ``c_parser_min_bytes``: as :func:`read`'s."""
    if is_bag(path):
        return None
    traj = text.read_trajectory(
        path,
        opts.get("format", "auto"),
        time_unit=opts.get("time_unit", "auto"),
        on_unsorted=opts.get("unsorted", "error"),
        kitti_printed=True,  # tells a KITTI file (printed blocks) from the others
        printed_quaternions=True,
        c_parser_min_bytes=c_parser_min_bytes,
    )
    return None if traj.r_printed is not None or traj.position_only else traj


def read(
    path,
    opts: dict,
    *,
    notes: list | None = None,
    kitti_times=None,
    c_parser_min_bytes: int = text.C_PARSER_MIN_BYTES,
    table: text.TableAhead | None = None,
) -> Trajectory:
    """Read a source (bag or text file) into seconds and unit quaternions; what was inferred goes to
    ``notes`` and the log. ``c_parser_min_bytes``: text files from this size on are parsed by
    pandas' C parser (:func:`epa.readers.text.read_table`). ``table``: a text file's table already
    started (:class:`epa.readers.text.TableAhead`)."""
    path = Path(path)
    if is_bag(path):
        from epa.readers import bags  # (a bag only: a text file never compiles its reader)

        own: list[str] = []
        try:
            traj = bags.read_bag(
                path,
                opts.get("topic"),
                frames=opts.get("frames"),
                stamp=opts.get("stamp", "header"),
                static_topic=opts.get("static_topic") or "/tf_static",
                tf_rate=opts.get("tf_rate"),
                notes=own,
            )
        except EpaError as exc:
            if exc.path is None:
                raise EpaError(exc.message, path=f"{path} topic {opts.get('topic')}") from None
            raise
        traj = _bag_order(traj, path, opts, own)
        if notes is not None:
            notes.extend(own)
        return traj
    if opts.get("topic") or opts.get("frames"):
        raise EpaError(
            "a topic is set for this source but it is not a bag (.bag, .mcap or a ROS 2 bag folder)",
            path=str(path),
        )
    if opts.get("stamp", "header") != "header":  # a text file has only its own stamps
        raise EpaError(
            f"stamp: {opts['stamp']} is set for this source but it is not a bag (set it in"
            " sources.<...>.stamp for the bag sources only)",
            path=str(path),
        )
    traj = text.read_trajectory(
        path,
        opts.get("format", "auto"),
        time_unit=opts.get("time_unit", "auto"),
        on_unsorted=opts.get("unsorted", "error"),
        kitti_rate=opts.get("kitti_rate", 10.0),
        kitti_times=kitti_times,
        kitti_printed=opts.get("kitti_printed", False),
        notes=notes,
        c_parser_min_bytes=c_parser_min_bytes,
        table=table,
    )
    if traj.cov_rot is not None and opts.get("orientation_covariance") == "global":
        traj = Trajectory(
            traj.t,
            traj.p,
            traj.q,
            cov_rot=geometry.local_covariance(traj.r, traj.cov_rot),
            cov_pos=traj.cov_pos,
        )
        if notes is not None:
            notes.append("orientation covariance converted from global to local")
    return traj


def _bag_order(traj: Trajectory, path: Path, opts: dict, notes: list) -> Trajectory:
    """Bag stamps follow the same rules as a file's: repeats and backward steps stop, unless sorting
    was asked for; every repair is a note."""
    where = f"{path} topic {opts.get('topic') or '(auto)'}"
    k = text.beyond_reach(traj.p)
    if k is not None:
        raise EpaError(f"message {k + 1}: position beyond {text.MAX_POSITION_M:.0e} m", path=where)
    try:
        traj, note = text.in_order(traj, opts.get("unsorted", "error"))
    except text.Unordered as bad:
        raise EpaError(
            f"message {bad.k + 1}: stamp {float(traj.t[bad.k])!r} {bad.what} (set unsorted: sort to sort"
            " and drop duplicates)",
            path=where,
        ) from None
    if note is not None:
        notes.append(note)
        log.warning("%s: %s", path, note)  # a repair is a warning; what was read is a note
    if len(traj) < 2:
        raise EpaError(f"only {len(traj)} pose(s); at least 2 are needed", path=where)
    return traj


def describe(path, traj: Trajectory, notes: list[str]) -> str:
    """One paragraph about a read source: what it was read as, poses, duration, rate, path length."""
    n = len(traj)
    span = float(traj.t[-1] - traj.t[0]) if n else 0.0
    rate = (n - 1) / span if span > 0 else float("nan")
    cov = ", with covariance" if traj.cov_rot is not None else ""
    read_as = "; ".join(notes) or "as configured"
    return (
        f"{path}: {read_as}\n  {n} poses{cov}, {span:.3f} s ({traj.t[0]:.6f} .. {traj.t[-1]:.6f}),"
        f" {rate:.2f} Hz, path length {traj.length():.3f} m"
    )
