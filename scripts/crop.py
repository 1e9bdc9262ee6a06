"""Rule crop: optional time window."""
from epa import io, pipeline
from epa.workflow import stage

with stage(snakemake):
    ref, est, info = pipeline.crop(io.read_tum_file(snakemake.input.ref), io.read_tum_file(snakemake.input.est),
                                   snakemake.params.cfg)
    io.write_tum(snakemake.output.ref, ref)
    io.write_tum(snakemake.output.est, est)
    io.write_json(snakemake.output.info, info)
