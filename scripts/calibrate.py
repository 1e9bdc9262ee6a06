"""Rule calibrate: Step 2 extrinsic; writes the corrected estimate beside its reference."""
from epa import io, pipeline
from epa.workflow import stage

with stage(snakemake):
    ref, est = io.read_pairs(snakemake.input.pairs)
    corrected, info = pipeline.calibrate_stage(ref, est, snakemake.params.cfg, io.read_json(snakemake.input.sync))
    io.write_pairs(snakemake.output.pairs, ref, corrected)
    io.write_json(snakemake.output.info, info)
