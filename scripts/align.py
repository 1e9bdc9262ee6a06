"""Rule align: Step 3 world-frame alignment."""
from epa import io, pipeline
from epa.workflow import stage

with stage(snakemake):
    ref, est = io.read_pairs(snakemake.input.pairs)
    _, aligned, info = pipeline.align_stage(ref, est, snakemake.params.cfg, io.read_json(snakemake.input.calibrate))
    io.write_pairs(snakemake.output.pairs, ref, aligned)
    io.write_tum(snakemake.output.aligned, aligned)
    io.write_json(snakemake.output.transform, info)
