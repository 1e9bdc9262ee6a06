"""Rule load: read the reference and the estimate in any supported format; write them as TUM."""
from epa import io, pipeline
from epa.workflow import stage

with stage(snakemake):
    ref, est, info = pipeline.load(snakemake.input.truth, snakemake.input.estimate, snakemake.params.cfg)
    io.write_tum(snakemake.output.ref, ref)
    io.write_tum(snakemake.output.est, est)
    io.write_json(snakemake.output.info, info)
