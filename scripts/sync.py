"""Rule sync: Step 1 time offset, then association; writes the matched pairs."""
from epa import io, pipeline
from epa.workflow import stage

with stage(snakemake):
    ref, est, info, curve = pipeline.sync_stage(io.read_tum_file(snakemake.input.ref),
                                                io.read_tum_file(snakemake.input.est), snakemake.params.cfg)
    io.write_pairs(snakemake.output.pairs, ref, est)
    io.write_csv(snakemake.output.xcorr, curve or {"lag_s": [], "corr": []})
    io.write_json(snakemake.output.info, info)
