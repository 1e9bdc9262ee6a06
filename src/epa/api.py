"""The Python API, for notebooks and scripts: :func:`evaluate` one reference and estimate (the stages
of ``epa eval``, in this process), :func:`read_results` a grid's results as a table,
:func:`read_cells` every cell of its tables, :func:`read_case` one case's records and per-pose
errors; and the building blocks, one step at a time: :func:`read_trajectory`, :func:`associate`,
:func:`align`, :func:`ape`, :func:`rpe` and :func:`stats` (the stages' own functions).
``import epa`` reaches these lazily: it imports neither Snakemake nor matplotlib, and pandas only
when a table is asked for.
"""

from __future__ import annotations

import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from epa.artifacts.case import Case, CaseData, CaseFolder, Record, read_record
from epa.core.errors import EpaError
from epa.core.trajectory import Trajectory
from epa.metrics.accuracy import stats
from epa.steps.align import Similarity

__all__ = [
    "Result",
    "Similarity",
    "Trajectory",
    "align",
    "ape",
    "associate",
    "evaluate",
    "read_case",
    "read_cells",
    "read_results",
    "read_trajectory",
    "rpe",
    "stats",
]

# the name `epa eval` gives its one estimate in `sources.algorithms` (the same settings apply)
ESTIMATE = "estimate"


# Derived from the stage declarations on each use (module __getattr__ below), so that a stage added
# to the list reaches epa.evaluate and read_case:
# SETTINGS: the config sections a keyword argument may set, those the stages read in the schema's
#   order (the folders and the grid's own are the workflow's);
# RECORDS: each stage's record as CaseData names it (align's record is Step 3's transform);
# ARRAYS: the per-pose and per-pair tables the metrics stage hands on (06_metrics/, the files' stems).
SETTINGS: tuple[str, ...]
RECORDS: dict[str, str]
ARRAYS: tuple[str, ...]


def _records() -> dict[str, str]:
    from epa.workflow import chain

    return chain.RECORDS


def _arrays() -> tuple[str, ...]:
    from epa.workflow import chain

    return tuple(v.name for v in chain.BY_NAME["metrics"].values if v.type is not Record)


def _settings() -> tuple[str, ...]:
    from epa.workflow import chain
    from epa.workflow import settings as workflow_settings

    read = {s for st in chain.STAGES for s in chain.sections_for(st.name)}
    read -= set(workflow_settings.GRID_FOLDERS)
    return tuple(k for k in workflow_settings.defaults() if k in read)


_DERIVED = {"RECORDS": _records, "ARRAYS": _arrays, "SETTINGS": _settings}


def __getattr__(name: str):
    if name in _DERIVED:
        return _DERIVED[name]()
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


@dataclass(frozen=True)
class Result:
    """One case, evaluated (:func:`evaluate`) or read back (:func:`read_case`).

    ``records``: each stage's record by stage name (``load`` ... ``efficiency``; a failed stage's is
    ``{"status": "failed", "reason": ...}``). ``errors``: per matched pose, 06_metrics/ape.csv's
    columns (``t``, ``dist_m``, ``trans_m``, ``rot_deg``, ``yaw_deg``, ``trans_xy_m``) as arrays.
    ``relative``: the distance and 1 s RPE pairs (``rpe_segments``, ``rpe_time``) as column arrays.
    Empty where the case folder holds no arrays (a grid run with them off, a failed case).
    """

    name: str
    records: dict = field(repr=False)
    errors: dict = field(repr=False)
    relative: dict = field(repr=False)
    folder: Path | None = None

    @property
    def metrics(self) -> dict:
        return self.records["metrics"]

    @property
    def status(self) -> str:
        reason = self.reason
        return "ok" if reason is None else "failed"

    @property
    def reason(self) -> str | None:
        """Why the case failed: the first failed stage's reason (None: it has a result)."""
        for record in self.records.values():
            if record.get("status") == "failed":
                return record.get("reason", "failed")
        return None

    @property
    def ate_rmse_m(self) -> float | None:
        return _dig(self.metrics, "ate", "trans_m", "rmse")

    @property
    def ate_rot_rmse_deg(self) -> float | None:
        return _dig(self.metrics, "ate", "rot_deg", "rmse")

    def headline(self) -> dict:
        """The numbers summary.csv leads with, under its column names."""
        m = self.metrics
        return {
            "status": self.status,
            "eval_source": m.get("eval_source"),
            "n_matched": m.get("n_matched"),
            "ate_trans_rmse_m": self.ate_rmse_m,
            "ate_rot_rmse_deg": self.ate_rot_rmse_deg,
            "time_offset_s": m.get("time_offset_s"),
        }

    def to_frame(self, table: str = "errors"):
        """A pandas DataFrame: the per-pose ``errors`` (default) or one ``relative`` table."""
        import pandas

        columns = self.errors if table == "errors" else self.relative.get(table)
        if columns is None:
            known = ", ".join(("errors", *self.relative))
            raise EpaError(f"to_frame: no table {table!r} (known: {known})")
        return pandas.DataFrame({k: np.asarray(v) for k, v in columns.items()})


def _dig(record: dict, *keys):
    value: object = record
    for k in keys:
        if not isinstance(value, dict):
            return None
        value = value.get(k)
    return value


def settings(config=None, **given) -> dict:
    """A resolved config from a config file or mapping (``config``) and keyword settings, each a
    section (``align={"method": "sim3"}``) or ``mode``; ``reference_source`` / ``estimate_source``
    are the two sides' source settings (``sources.reference``, ``sources.algorithms.estimate``)."""
    from epa.workflow import settings as workflow_settings

    allowed = _settings()
    unknown = sorted(set(given) - set(allowed) - {"reference_source", "estimate_source"})
    if unknown:
        raise EpaError(
            f"epa.evaluate: unknown setting {unknown[0]!r} (settings: {', '.join(allowed)},"
            " reference_source, estimate_source)"
        )
    if isinstance(config, (str, Path)):
        cfg = workflow_settings.load_yaml(config)
    else:
        cfg = dict(config or {})
    cfg.pop("inputs", None)  # a grid's: this is one case
    cfg.update(truth_dir=".", algorithms_dir=".")
    cfg.setdefault("report", {"per_case": False})  # no figures (and no matplotlib) unless asked
    sources = cfg.setdefault("sources", {})
    if "reference_source" in given:
        sources["reference"] = given.pop("reference_source")
    if "estimate_source" in given:
        sources.setdefault("algorithms", {})[ESTIMATE] = given.pop("estimate_source")
    for key, value in given.items():
        if isinstance(value, dict) and isinstance(cfg.get(key), dict):
            cfg[key] = {**cfg[key], **value}
        else:
            cfg[key] = value
    return workflow_settings.resolve(cfg, source="epa.evaluate")


def evaluate(reference, estimate, *, config=None, out_dir=None, **settings_) -> Result:
    """Evaluate one estimate against its reference, as ``epa eval`` does (the same stages, the same
    records). ``settings_``: config sections as keyword arguments (see :func:`settings`).
    ``out_dir``: keep the case folder there, with every stage's arrays; None: a temporary folder,
    removed (the result holds the records and per-pose errors in memory). A user mistake raises
    :class:`epa.core.errors.EpaError` (one line naming the file or the setting)."""
    from epa import readers
    from epa.workflow import chain

    cfg = settings(config, **settings_)

    def run(folder) -> Result:
        data = chain.run_case_data(
            reference,
            estimate,
            folder,
            cfg,
            write_arrays=out_dir is not None,
            ref_source=readers.options(cfg, "reference"),
            est_source=readers.options(cfg, "estimate", algorithm=ESTIMATE),
            keep=tuple(_records().values()) + _arrays(),
        )
        return _result(Path(estimate).stem, data, None if out_dir is None else Path(folder))

    if out_dir is not None:
        return run(out_dir)
    with tempfile.TemporaryDirectory(prefix="epa-") as tmp:
        return run(tmp)


def _result(name: str, data: CaseData, folder: Path | None) -> Result:
    records = {stage: getattr(data, attr) for stage, attr in _records().items()}
    relative = {k: dict(getattr(data, k)) for k in _arrays()[1:]}
    return Result(name, records, dict(data.ape), relative, folder)


def read_case(results_dir, case: str) -> Result:
    """One case of a grid's results (``<algorithm>/<dataset>/<run>``), read from its folder: every
    stage's record (a failed one's marker), and its arrays where the run wrote them."""
    folder = CaseFolder.of(results_dir, Case.from_key(case))
    if not folder.root.is_dir():
        raise EpaError(f"no case {case!r} in {results_dir}", path=str(folder.root))
    from epa.workflow import chain

    records = {}
    for stage in _records():
        name = chain.BY_NAME[stage].records[0]
        path = folder.path(stage, name)
        records[stage] = read_record(path)[0] if path.is_file() else _missing(stage)
    arrays = {}
    arrays_named = _arrays()
    for name in arrays_named:
        path = folder.path("metrics", f"{name}.csv")
        arrays[name] = folder.table("metrics", f"{name}.csv") if _usable(path) else {}
    relative = {k: arrays[k] for k in arrays_named[1:]}
    return Result(case, records, arrays["ape"], relative, folder.root)


def _missing(stage: str) -> dict:
    return {"status": "failed", "reason": f"{stage}: not run (no record)"}


def _usable(path: Path) -> bool:
    from epa.artifacts.case import failure_of

    return path.is_file() and failure_of(path) is None


def read_results(results_dir):
    """Every case of a grid's results as a pandas DataFrame: ``case`` (its key), ``summary.csv``'s
    columns (status, headline numbers, notes), and ``folder``. A case folder summary.csv does not
    list (a run stopped before the tables) is a row with the status its records give. Per-case
    arrays: :func:`read_case`."""
    import pandas

    root = Path(results_dir)
    summary = root / "summary.csv"
    if not summary.is_file():
        raise EpaError("no summary.csv: run the workflow (or its tables) first", path=str(root))
    frame = pandas.read_csv(summary, dtype={"algorithm": str, "dataset": str, "run": str})
    frame.insert(0, "case", frame["algorithm"] + "/" + frame["dataset"] + "/" + frame["run"])
    listed = set(frame["case"])
    extra = []
    for folder in sorted((root / "cases").glob("*/*/*")):
        key = "/".join(folder.parts[-3:])
        if folder.is_dir() and key not in listed:
            result = read_case(root, key)
            alg, ds, run = key.split("/")
            row = {"case": key, "algorithm": alg, "dataset": ds, "run": run}
            extra.append({**row, **result.headline(), "notes": result.reason})
    if extra:
        frame = pandas.concat([frame, pandas.DataFrame(extra)], ignore_index=True)
    frame["folder"] = [str(root / "cases" / key) for key in frame["case"]]
    return frame


def read_cells(results_dir):
    """Every cell of a grid's tables as a pandas DataFrame, one row per number (``cells.csv``):
    ``algorithm``, ``dataset`` (``Average``: the table's Average column; ``all``: a cell pooling
    every dataset), ``metric`` (the table's name, or ``cases`` / ``alignment``), ``statistic``,
    ``value``, ``spread``, ``n`` and ``marks`` (docs/outputs.md)."""
    import pandas

    path = Path(results_dir) / "cells.csv"
    if not path.is_file():
        raise EpaError("no cells.csv: run the workflow (or its tables) first", path=str(path))
    # names stay text (a dataset "01", an algorithm "nan"); an empty number is missing
    text = dict.fromkeys(("algorithm", "dataset", "metric", "statistic", "marks"), str)
    missing = {"value": [""], "spread": [""], "n": [""]}
    frame = pandas.read_csv(
        path, dtype={**text, "n": "Int64"}, keep_default_na=False, na_values=missing
    )
    return frame


# ----------------------------------------------------------------------------- building blocks
def read_trajectory(path, format: str = "auto", **source) -> Trajectory:
    """A trajectory file or bag topic, read as the workflow reads a reference: ``format`` (auto,
    tum, kitti, euroc, openvins, csv, position) and the other keys of a ``sources.*`` setting
    (``topic``, ``frames``, ``stamp``, ``time_unit``, ``unsorted``, ...)."""
    from epa import readers
    from epa.workflow import settings as workflow_settings

    opts = readers.options(workflow_settings.defaults(), "reference")
    unknown = sorted(set(source) - set(opts))
    if unknown:
        raise EpaError(
            f"epa.read_trajectory: unknown setting {unknown[0]!r} (settings: {', '.join(opts)})"
        )
    return readers.read(path, {**opts, **source, "format": format})


def associate(
    ref: Trajectory,
    est: Trajectory,
    *,
    policy: str = "evo",
    max_diff: float | None = None,
    offset: float = 0.0,
) -> tuple[Trajectory, Trajectory]:
    """The matched poses of both sides, pose for pose (Step 1's association): ``policy`` evo,
    ov_eval or rpg, ``max_diff`` its tolerance in seconds (default: the policy's), ``offset`` added
    to the estimate's stamps (t_ref = t_est + offset)."""
    from epa.steps import sync

    i_ref, i_est = sync.associate(ref, est, policy=policy, max_diff=max_diff, offset=offset)
    return ref.select(i_ref), est.select(i_est)


def _matched(ref: Trajectory, est: Trajectory, what: str) -> None:
    if len(ref) != len(est):
        raise EpaError(
            f"epa.{what}: {len(ref)} reference and {len(est)} estimate poses; associate them first"
        )


def align(
    ref: Trajectory, est: Trajectory, *, method: str = "se3", first_n: int = -1
) -> tuple[Trajectory, Similarity]:
    """The estimate in the reference's world frame, and the fit (Step 3): ``method`` se3, sim3,
    posyaw or none, on the first ``first_n`` matched poses (-1: all). Both sides matched pose for
    pose (:func:`associate`)."""
    from epa.steps import align as step

    _matched(ref, est, "align")
    fit = step.fit(ref, est, method=method, first_n=first_n)
    return fit.apply(est), fit


def _rows(ref: Trajectory, est: Trajectory):
    from epa.core import geometry

    return geometry.pair_rows(None, ref.p, est.p, q=(ref.q, est.q))


def _errors(trans, rot, ref: Trajectory, est: Trajectory) -> dict:
    """A position-only side has no rotation error to give."""
    if ref.position_only or est.position_only:
        return {"trans_m": trans}
    return {"trans_m": trans, "rot_deg": rot}


def ape(ref: Trajectory, est: Trajectory) -> dict:
    """Per matched pose, the absolute errors of an aligned estimate: ``trans_m`` (position, m) and
    ``rot_deg`` (orientation angle, deg) arrays; :func:`stats` gives their rmse, mean, ..."""
    from epa.metrics import accuracy

    _matched(ref, est, "ape")
    trans, rot = accuracy.ape(ref, est, rows=None if ref.position_only else _rows(ref, est))
    return _errors(trans, rot, ref, est)


def rpe(
    ref: Trajectory,
    est: Trajectory,
    *,
    delta: float = 1.0,
    unit: str = "m",
    all_pairs: bool = False,
) -> dict:
    """The relative errors of pose pairs ``delta`` apart (``unit``: frames, m, s, deg, rad), the
    pairs chosen on the estimate as evo chooses them (consecutive, or every start with
    ``all_pairs``): ``i``, ``j`` (pose indices), ``trans_m`` and ``rot_deg`` arrays."""
    from epa.core import geometry
    from epa.metrics import accuracy

    _matched(ref, est, "rpe")
    i, j = accuracy.evo_pairs(est, delta, unit, all_pairs=all_pairs)
    if ref.position_only or est.position_only:
        identity = np.tile([0.0, 0.0, 0.0, 1.0], (len(ref), 1))
        rows = geometry.pair_rows(identity, ref.p, est.p)
    else:
        rows = _rows(ref, est)
    rot, trans = geometry.pair_errors(rows, i, j)
    return {"i": np.asarray(i), "j": np.asarray(j), **_errors(trans, rot, ref, est)}
