"""Case discovery in the OpenVINS layout: truth/<dataset>.<ext>, algorithms/<algorithm>/<dataset>/<run>.<ext>."""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path

from epa.errors import EpaError

log = logging.getLogger("epa")
SIDE_FILES = ("_times.txt", "times.txt", ".yaml", ".yml", ".md", ".json")  # not trajectories


@dataclass(frozen=True)
class Case:
    algorithm: str
    dataset: str
    run: str
    estimate: Path
    truth: Path

    @property
    def key(self) -> str:
        return f"{self.algorithm}/{self.dataset}/{self.run}"


def _trajectory_files(folder: Path):
    # a dangling link is kept: its case then fails with "file not found" instead of vanishing
    return sorted(p for p in folder.iterdir() if (p.is_file() or p.is_symlink()) and not p.name.startswith(".")
                  and not p.name.endswith(SIDE_FILES))


def discover(truth_dir, algorithms_dir) -> tuple[dict[str, Path], list[Case]]:
    truth_dir, algorithms_dir = Path(truth_dir), Path(algorithms_dir)
    for d, key in ((truth_dir, "truth_dir"), (algorithms_dir, "algorithms_dir")):
        if not d.is_dir():
            raise EpaError(f"{key} is not a folder", path=str(d))
    truth: dict[str, Path] = {}
    for p in _trajectory_files(truth_dir):
        if p.stem in truth:
            raise EpaError(f"two reference files for dataset {p.stem!r} ({truth[p.stem].name}, {p.name})", path=str(p))
        truth[p.stem] = p
    cases = []
    for alg in sorted(d for d in algorithms_dir.iterdir() if d.is_dir() and not d.name.startswith(".")):
        for ds in sorted(d for d in alg.iterdir() if d.is_dir()):
            if ds.name not in truth:
                log.warning("%s: no reference %s/%s.* - skipped", ds, truth_dir, ds.name)
                continue
            for run in _trajectory_files(ds):
                cases.append(Case(alg.name, ds.name, run.stem, run, truth[ds.name]))
    if not cases:
        raise EpaError("no estimate matches a reference (expected <algorithm>/<dataset>/<run>.<ext>)",
                       path=str(algorithms_dir))
    return truth, cases
