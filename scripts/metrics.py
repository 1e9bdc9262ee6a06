"""Rule metrics: ATE, distance/time RPE, drift rate; per-pose and per-pair errors as CSV."""
from epa import io, pipeline
from epa.workflow import stage

with stage(snakemake):
    ref, est = io.read_pairs(snakemake.input.pairs)
    summary, tables = pipeline.metrics_stage(ref, est, snakemake.params.cfg)
    record = pipeline.case_record(io.read_json(snakemake.input.sync), io.read_json(snakemake.input.calibrate),
                                  io.read_json(snakemake.input.transform), summary)
    io.write_csv(snakemake.output.ape, tables["ape"])
    io.write_csv(snakemake.output.segments, tables["rpe_segments"])
    io.write_csv(snakemake.output.time, tables["rpe_time"])
    io.write_json(snakemake.output.metrics, record)
