"""Rule drift: fail segments, success rate, drift-valid metrics."""
from epa import io, pipeline
from epa.workflow import stage

with stage(snakemake):
    tables = {"ape": io.read_csv(snakemake.input.ape), "rpe_segments": io.read_csv(snakemake.input.segments),
              "rpe_time": io.read_csv(snakemake.input.time)}
    summary, artifacts = pipeline.drift_stage(tables, snakemake.params.cfg)
    io.write_csv(snakemake.output.fail_segments, artifacts["fail_segments"])
    io.write_csv(snakemake.output.pose_valid, artifacts["pose_valid"])
    io.write_csv(snakemake.output.segments, artifacts["rpe_segments"])
    io.write_csv(snakemake.output.time, artifacts["rpe_time"])
    io.write_json(snakemake.output.drift, summary)
