"""The records of every case as the tables read them (:class:`CaseResult`), read from the case folders."""

from __future__ import annotations

from dataclasses import dataclass, field

from epa.artifacts import stage as stage_list
from epa.artifacts.case import Case, CaseFolder
from epa.core.errors import EpaError
from epa.metrics import accuracy, drift, registry
from epa.outputs import parallel


def has_result(status: str) -> bool:
    """Whether a case's status carries numbers (a globally failed case still has them)."""
    return status == "ok" or status.startswith("globally failed")


@dataclass
class CaseResult:
    """A case's records as the tables read them. ``records`` holds the records of the stages after
    drift (consistency, efficiency), each ``{"available": False, "failed": reason}`` if that stage
    failed; ``segments`` / ``time`` are the per-pair RPE errors with their drift validity (only the
    columns the tables read, ``valid`` as booleans, the segment lengths as runs of rows where they
    are: :func:`_pairs`), ``ape`` the per-pose APE results/consistency/
    reads; a large grid holds these for every case at once (docs/performance.md)."""

    case: Case
    status: str = "ok"
    load: dict = field(default_factory=dict)
    sync: dict = field(default_factory=dict)  # 03_sync/sync.json
    metrics: dict = field(default_factory=dict)
    drift: dict = field(default_factory=dict)
    segments: dict = field(default_factory=dict)
    time: dict = field(default_factory=dict)
    ape: dict = field(default_factory=dict)
    records: dict = field(default_factory=dict)
    # how it was evaluated (marks.evaluation), made when a table first asks
    _evaluation: object = field(default=None, repr=False, compare=False)

    algorithm = property(lambda self: self.case.algorithm)
    dataset = property(lambda self: self.case.dataset)
    run = property(lambda self: self.case.run)

    @property
    def ok(self) -> bool:
        return has_result(self.status)

    def record_of(self, metric) -> dict:
        """A registered metric's record (:mod:`epa.metrics.registry`): ``metrics.json``'s entry for
        one the metrics stage computes, else its own stage's record; {} when there is none."""
        if metric.stage == "metrics":
            return self.metrics.get(metric.key) or {}
        return self.records.get(metric.stage, {})


# Below this many cases one process reads them all: starting workers costs more than it saves.
PARALLEL_FROM_CASES = 64
# A worker hands back this many cases at a time: one share of a 10,000-case grid pickled whole was a
# second copy of it in the worker and in this process at once.
SHARE_CASES = 256


def collect(keys: list[str], results_dir, workers: int = 1) -> list[CaseResult]:
    """Read every case's artifacts (``<results_dir>/cases/<algorithm>/<dataset>/<run>/``), in the
    order of ``keys``. ``workers`` > 1 reads contiguous shares of a large grid in forked processes:
    reading is most of the tables rule, the grid's serial tail (10 of 15 s on 1,000 cases)."""
    if workers <= 1 or len(keys) < PARALLEL_FROM_CASES:
        return _collect(keys, results_dir)
    step = min(SHARE_CASES, -(-len(keys) // workers))
    shares = [(keys[k : k + step], results_dir) for k in range(0, len(keys), step)]
    return [c for part in parallel.map_forked(_collect, shares, workers) for c in part]


def _collect(keys: list[str], results_dir) -> list[CaseResult]:
    out = []
    for key in keys:
        try:
            case = Case.from_key(key)
            folder = CaseFolder.of(results_dir, case)
        except EpaError as exc:  # no folder was ever written for it: marked failed under its name
            out.append(CaseResult(Case.unchecked(key), status="failed: " + exc.one_line()))
            continue
        res = CaseResult(case)
        load, load_failed = folder.record_or_failure("load", "load.json")
        if load_failed is None:
            res.load = load
        drift, reason = folder.record_or_failure("drift", "drift.json")
        if reason is not None:
            res.status = reason if reason.startswith("internal error") else "failed: " + reason
        else:
            res.sync = folder.record("sync", "sync.json")
            res.metrics = folder.record("metrics", "metrics.json")
            res.drift = drift
            res.segments = _pairs(folder, "rpe_segments", ("length_m", "rot_deg", "trans_m"))
            res.time = _pairs(folder, "rpe_time", ("rot_deg", "trans_m"))
            res.ape = _columns(folder.table("metrics", "ape.csv"), ("t", "trans_m", "rot_deg"))
            if res.drift.get("status"):
                res.status = res.drift["status"]
            for stage in AFTER_DRIFT:
                if folder.has(stage, f"{stage}.json"):
                    record, failed = folder.record_or_failure(stage, f"{stage}.json")
                    res.records[stage] = (
                        record if failed is None else {"available": False, "failed": failed}
                    )
        out.append(res)
    return out


def _columns(table: dict, names) -> dict:
    """Copies of some columns: a parsed table's columns are views of its whole array, which would
    otherwise stay in memory (the case indices and stamps the tables never read)."""
    return {n: table[n].copy() for n in names if n in table}


def _pairs(folder: CaseFolder, name: str, columns) -> dict:
    """A relative-error table's columns the tables read, with its drift validity as booleans (the
    tables select ``valid > 0``). Where each segment length's pairs are one run of rows, as the
    metrics stage writes them, ``length_runs`` ({length: slice}) replaces the ``length_m`` column:
    a cell takes a length's pairs as a view instead of comparing every pair of every run for each
    of its cells (the per-algorithm tables did so 480,000 times on 10,000 cases)."""
    out = _columns(folder.table("metrics", f"{name}.csv"), columns)
    runs = drift.length_runs(out["length_m"]) if "length_m" in out else None
    if runs is not None:
        out["length_runs"] = runs
        del out["length_m"]
    valid = folder.table("drift", f"{name}_valid.csv").get("valid")
    if valid is not None:
        out["valid"] = valid > 0
    return out


# The stages after drift whose records the tables read: those computing a registered metric of their
# own (consistency, efficiency), in the order they run. Their failure leaves the accuracy standing.
AFTER_DRIFT = tuple(
    stage
    for stage in stage_list.ORDER
    if stage != "metrics" and any(m.stage == stage for m in registry.REGISTRY)
)


def failed_cases(grid: list[CaseResult]) -> list[tuple[str, str]]:
    """(case key, status) of every case without a result, for the end-of-run list."""
    return [(f"{c.algorithm}/{c.dataset}/{c.run}", c.status) for c in grid if not c.ok]


def segments_by_dataset(grid: list[CaseResult]) -> dict[str, list[float]]:
    """Each dataset's distance-RPE segment lengths, as its cases were evaluated (the first case with
    a result of each dataset; its settings may be its own: overrides, ``segments: auto``)."""
    out: dict[str, list[float]] = {}
    for c in grid:
        if c.ok and c.dataset not in out and c.metrics.get("rpe_distance") is not None:
            out[c.dataset] = accuracy.recorded_lengths(c.metrics)
    return out
