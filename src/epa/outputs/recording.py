"""A Rerun recording (``.rrd``) of one case, from its artifacts: the reference and the aligned
estimate as 3-D paths, the estimate's position over time, and the errors over time (APE, and NEES
where covariance exists). Open it with ``rerun <file>.rrd``.

Behind the ``rerun`` extra (``pip install "epica[rerun]"``): ``rerun`` is imported here only, and
only when ``report.rerun`` is on; the setting is refused at config time when the extra is missing.
"""

from __future__ import annotations

import importlib.util
import uuid

import numpy as np

from epa.core.errors import EpaError
from epa.outputs.figures import OKABE_ITO

INSTALL_HINT = 'report.rerun needs the rerun extra: pip install "epica[rerun]"'


def available() -> bool:
    return importlib.util.find_spec("rerun") is not None


def _rgb(hex_colour: str) -> list[int]:
    return [int(hex_colour[k : k + 2], 16) for k in (1, 3, 5)]


def write_rrd(data, name: str, out) -> None:
    """Write ``out`` (.rrd) from a case's artifacts (:class:`epa.artifacts.case.CaseData`); atomic
    like every artifact."""
    if not available():
        raise EpaError(INSTALL_HINT)
    import rerun as rr

    ref, aligned, ape = data.matched[0], data.aligned, data.ape
    # a recording id derived from the case name: the same case gives the same id on a re-run
    rec = rr.RecordingStream(
        "epica", recording_id=uuid.uuid5(uuid.NAMESPACE_URL, f"epica:{name}"), send_properties=False
    )
    tmp = out.with_name("." + out.name + ".tmp")
    rec.save(str(tmp))
    rec.log(
        "world/reference",
        rr.LineStrips3D([data.cropped[0].p], colors=[[150, 150, 150]], radii=[0.02]),
        static=True,
    )
    rec.log(
        "world/estimate",
        rr.LineStrips3D([aligned.p], colors=[_rgb(OKABE_ITO[0])], radii=[0.02]),
        static=True,
    )
    times = rr.TimeColumn("time", duration=ref.t - ref.t[0])
    rec.send_columns(
        "world/estimate/now",
        indexes=[times],
        columns=rr.Points3D.columns(positions=aligned.p).partition(np.ones(len(aligned), int)),
    )
    rec.send_columns(
        "world/reference/now",
        indexes=[times],
        columns=rr.Points3D.columns(positions=ref.p).partition(np.ones(len(ref), int)),
    )
    series = {"errors/ape_m": ape["trans_m"], "errors/ape_rot_deg": ape["rot_deg"]}
    n = data.nees
    if n:
        t_nees = rr.TimeColumn("time", duration=n["t"] - ref.t[0])
        for key in ("nees_pos", "nees_rot"):
            rec.send_columns(
                f"consistency/{key}", indexes=[t_nees], columns=rr.Scalars.columns(scalars=n[key])
            )
    for entity, values in series.items():
        rec.send_columns(entity, indexes=[times], columns=rr.Scalars.columns(scalars=values))
    rec.flush()
    rec.disconnect()
    tmp.replace(out)
