"""Rule tables: error_comparison.txt, one .tex per LaTeX table, summary.csv."""
from epa import tables
from epa.workflow import stage

with stage(snakemake, check_inputs=False):
    grid = tables.collect(snakemake.params.cases, snakemake.input)
    tables.write_all(grid, snakemake.output, snakemake.params.cfg)
