"""Crop: keep the part of both trajectories the ``crop`` settings select (02_crop/)."""

from __future__ import annotations

import numpy as np

from epa.artifacts.case import Both, CaseData, Record
from epa.artifacts.stage import Stage, Value
from epa.core.errors import EpaError
from epa.core.trajectory import Trajectory

NAME = "crop"


def compute(ref: Trajectory, est: Trajectory, cfg: dict):
    c = cfg["crop"]
    t0 = ref.t[0]
    lo = -np.inf if c["start"] is None else t0 + c["start"]
    hi = np.inf if c["end"] is None else t0 + c["end"]
    ref_c = ref.select((ref.t >= lo) & (ref.t <= hi))
    est_keep = (est.t >= lo) & (est.t <= hi) & (est.t >= est.t[0] + c["skip_first"])
    est_c = est.select(est_keep)
    if len(ref_c) < 2 or len(est_c) < 2:
        raise EpaError(
            f"the crop window leaves {len(ref_c)} reference and {len(est_c)} estimate poses"
        )
    return ref_c, est_c, record(cfg, {"n_ref": len(ref_c), "n_est": len(est_c)})


def cuts(cfg: dict) -> bool:
    """Whether the crop settings cut anything at all."""
    c = cfg["crop"]
    return c["start"] is not None or c["end"] is not None or c["skip_first"] > 0


def record(cfg: dict, counts: dict) -> dict:
    return {"settings": cfg["crop"], "n_ref": counts["n_ref"], "n_est": counts["n_est"]}


def run(data: CaseData, cfg: dict, write_arrays: bool) -> None:
    folder = data.folder
    if write_arrays and not cuts(cfg) and not data.known("loaded"):
        # nothing to cut: the loaded files are the cropped ones (linked, not read and rewritten)
        info = record(cfg, data.load_record)
        if all(folder.link("load", name, NAME) for name in ("ref.tum", "est.tum")):
            data.crop_record = info
            folder.write_record(NAME, "crop.json", info)
            return
    loaded_ref, loaded_est = data.loaded
    ref, est, info = compute(loaded_ref, loaded_est, cfg)
    data.cropped, data.crop_record = (ref, est), info
    if write_arrays:
        folder.write_tum(NAME, "ref.tum", ref)
        folder.write_tum(NAME, "est.tum", est)
    folder.write_record(NAME, "crop.json", info)


STAGE = Stage(
    name=NAME,
    run=run,
    settings=("crop",),
    records=("crop.json",),
    arrays=("ref.tum", "est.tum"),
    reads=("loaded", "load_record"),
    values=(
        Value("cropped", Both, lambda s: (s.f.tum(NAME, "ref.tum"), s.f.tum(NAME, "est.tum"))),
        Value("crop_record", Record, lambda s: s.f.record(NAME, "crop.json")),
    ),
)
