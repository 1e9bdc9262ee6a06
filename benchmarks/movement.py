"""How far a change between versions moves the results, by the rule for such changes
(docs/reproducibility.md, "Changes between versions"): Step 1's offset and Step 2's extrinsic and
scale against their own reported standard deviations, every other number relative to itself.

    python benchmarks/movement.py run --tree /path/to/old/checkout --out /tmp/mv/before
    python benchmarks/movement.py run --tree . --out /tmp/mv/after
    python benchmarks/movement.py compare /tmp/mv/before /tmp/mv/after

``run`` evaluates, with the epica of ``--tree`` (its ``src`` first on PYTHONPATH, its Snakefile):
the bundled example (config/config.yaml), every ``.test/*.yaml`` config, and, where
``../shared/data`` holds them, the rpg EuRoC estimates (vio_mono, vio_stereo, vislam_rp, vislam_ba
on MH_*) against OpenVINS's ground truth by ``epa eval --artifacts``. ``compare`` reads every
record and printed output of both folders number by number and prints the worst movements. The
drop-in outputs (mode ov_eval's and mode rpg's grids) are listed apart: the rule does not apply to
them, they must stay byte for byte.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT.parent / "shared" / "data"
GT = "rpng_open_vins/ov_data/euroc_mav"
RPG = "uzh-rpg_rpg_trajectory_evaluation/results"
ESTIMATES = (
    "euroc_mono_stereo/laptop/vio_mono",
    "euroc_mono_stereo/laptop/vio_stereo",
    "euroc_vislam_mono/laptop/vislam_rp",
    "euroc_vislam_mono/laptop/vislam_ba",
)
DROP_IN = ("ov_eval", "rpg")  # the .test configs whose grids are the tools' own outputs
FLOOR = 1e-12  # values zero up to rounding (the contract's absolute floor)
SKIPPED = ("provenance.json", "config.resolved.yaml", "verify.json", "report.json")
VOLATILE = ("10_report", "benchmarks", "logs", ".snakemake")  # times, paths: not results
_NUMBER = re.compile(r"(?<![\w.])[-+]?(?:\d+\.\d*|\.\d+|\d+)(?:[eE][-+]?\d+)?(?![\w.])")


# ----------------------------------------------------------------------------- run
def run(tree: Path, out: Path) -> None:
    env = {**os.environ, "PYTHONPATH": str(tree / "src")}
    out.mkdir(parents=True, exist_ok=True)
    configs = [tree / "config" / "config.yaml", *sorted((tree / ".test").glob("*.yaml"))]
    for cfg in configs:
        name = "example" if cfg.parent.name == "config" else cfg.stem
        cmd = [sys.executable, "-m", "snakemake", "--snakefile", str(tree / "Snakefile")]
        cmd += ["--configfile", str(cfg), "--cores", "2", "--nolock", "tables"]
        cmd += ["--config", f"results_dir={out / name}"]
        print(f"{name}: snakemake", flush=True)
        subprocess.run(cmd, cwd=tree, env=env, check=True, capture_output=True)
    if not (DATA / GT).is_dir():
        print(f"no {DATA}: the EuRoC cases are left out")
        return
    for est_dir in ESTIMATES:
        for est in sorted((DATA / RPG / est_dir).glob("*_MH_0*/stamped_*estimate*.txt")):
            seq = est.parent.name[-5:]
            (ref,) = (DATA / GT).glob(f"{seq}_*.txt")
            folder = out / "euroc" / est_dir.split("/")[-1] / seq / est.stem
            cmd = [sys.executable, "-m", "epa.cli.main", "eval", str(ref), str(est)]
            cmd += ["--out", str(folder), "--artifacts"]
            print(f"euroc {est_dir.split('/')[-1]} {seq} {est.stem}", flush=True)
            subprocess.run(cmd, cwd=tree, env=env, check=True, capture_output=True)


# ----------------------------------------------------------------------------- compare
class Worst:
    """The largest movement of one kind and where it is."""

    def __init__(self, label: str):
        self.label, self.value, self.where, self.count = label, 0.0, "", 0

    def see(self, value: float, where: str) -> None:
        self.count += 1
        if value > self.value or not self.where:
            self.value, self.where = value, where

    def __str__(self) -> str:
        return f"{self.label:<44}{self.value:10.3g}  ({self.count} values; worst at {self.where})"


def relative(a: float, b: float, floor: float = FLOOR) -> float:
    """|a - b| relative to the larger; 0 where both are zero up to rounding (``floor``)."""
    if a == b or (math.isnan(a) and math.isnan(b)):
        return 0.0
    diff = abs(a - b)
    return 0.0 if diff <= floor else diff / max(abs(a), abs(b))


def _numbers(x, path=""):
    """(path, value) of every number in a JSON document."""
    if isinstance(x, dict):
        for k, v in x.items():
            yield from _numbers(v, f"{path}.{k}")
    elif isinstance(x, list):
        for k, v in enumerate(x):
            yield from _numbers(v, f"{path}[{k}]")
    elif isinstance(x, (int, float)) and not isinstance(x, bool):
        yield path, float(x)


def _get(doc, path: str):
    for key in path.split("."):
        doc = doc.get(key) if isinstance(doc, dict) else None
    return doc


def _against_std(path: str, a_doc: dict) -> float | None:
    """The reported standard deviation an estimate of Step 1 or 2 is judged by, or None."""
    step1 = _get(a_doc, "step1")
    if path in (".step1.offset", ".step1.estimated", ".offset_s") and step1 and step1.get("used"):
        return step1.get("std")
    ext = _get(a_doc, "extrinsic")
    if not ext or not path.startswith(".extrinsic."):
        return None
    key = path.split(".")[2].split("[")[0]
    rot = [v for v in ext.get("rotation_std_deg") or [] if v is not None]
    trans = [v for v in ext.get("translation_std_m") or [] if v is not None]
    if key in ("rotation", "quaternion_xyzw") and rot:
        return math.radians(max(rot))  # entries of a rotation: radians of turn
    if key == "rotation_deg" and rot:
        return max(rot)
    if key in ("translation_m", "translation_norm_m") and trans:
        return max(trans)
    if key == "scale":
        return ext.get("scale_std")
    return None


def compare(before: Path, after: Path) -> int:
    step1, step2 = Worst("Step 1 offset / its std"), Worst("Step 2 extrinsic, scale / their std")
    others = Worst("other records (relative; 1e-12 floor)")
    bare = Worst("other records (relative, no floor)")
    printed = Worst("printed numbers that changed (relative)")
    drop_in, missing = [], []
    for pa in sorted(p for p in before.rglob("*") if p.is_file()):
        name = str(pa.relative_to(before))
        pb = after / name
        if pa.name in SKIPPED or any(f"/{d}/" in f"/{name}" for d in VOLATILE):
            continue
        if not pb.is_file():
            missing.append(name)
            continue
        ta, tb = pa.read_bytes(), pb.read_bytes()
        if name.split("/")[0] in DROP_IN:
            if ta != tb:
                drop_in.append(name)
            continue
        if ta == tb:
            continue
        if pa.suffix == ".json":
            da, db = json.loads(ta), json.loads(tb)
            na, nb = dict(_numbers(da)), dict(_numbers(db))
            if set(na) != set(nb):
                missing.append(f"{name} (other keys)")
            for path, x in na.items():
                y = nb.get(path, math.nan)
                std = _against_std(path, da) if pa.name in ("sync.json", "calibrate.json") else None
                if std:
                    worst = step1 if pa.name == "sync.json" else step2
                    worst.see(abs(x - y) / std, f"{name}:{path}")
                else:
                    others.see(relative(x, y), f"{name}:{path}")
                    bare.see(relative(x, y, 0.0), f"{name}:{path} {x!r} vs {y!r}")
        else:
            text_a, text_b = ta.decode(), tb.decode()
            xa, xb = _NUMBER.findall(text_a), _NUMBER.findall(text_b)
            if _NUMBER.sub("#", text_a) != _NUMBER.sub("#", text_b) or len(xa) != len(xb):
                missing.append(f"{name} (other text)")
                continue
            # a printed digit flips where the value lies at a rounding boundary: its change is
            # the printing's, reported apart (the value's own movement is in the records)
            text = pa.suffix in (".txt", ".tex") or pa.name == "summary.csv"
            for k, (x, y) in enumerate(zip(xa, xb)):
                if x != y:
                    where = f"{name}: number {k + 1} {x} vs {y}"
                    if text:
                        printed.see(relative(float(x), float(y), 0.0), where)
                    else:
                        others.see(relative(float(x), float(y)), where)
                        bare.see(relative(float(x), float(y), 0.0), where)
    for w in (step1, step2, others, bare, printed):
        print(w)
    print(f"drop-in outputs (mode {', '.join(DROP_IN)}) not byte-identical: {len(drop_in)}")
    for name in drop_in[:20] + missing[:20]:
        print("  " + name)
    if missing:
        print(f"missing or structurally different: {len(missing)}")
    ok = max(step1.value, step2.value) < 1e-3 and others.value < 1e-9
    ok = ok and not drop_in and not missing
    print("within the rule" if ok else "NOT within the rule")
    return 0 if ok else 1


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = ap.add_subparsers(dest="command", required=True)
    r = sub.add_parser("run")
    r.add_argument("--tree", type=Path, default=ROOT)
    r.add_argument("--out", type=Path, required=True)
    c = sub.add_parser("compare")
    c.add_argument("before", type=Path)
    c.add_argument("after", type=Path)
    args = ap.parse_args()
    if args.command == "run":
        run(args.tree.resolve(), args.out.resolve())
    else:
        sys.exit(compare(args.before, args.after))


if __name__ == "__main__":
    main()
