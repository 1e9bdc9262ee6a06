# epica: algorithm x dataset x run grid -> error_comparison tables. See README.md.
from snakemake.utils import min_version

min_version("8.0")


configfile: "config/config.yaml"


# validated against config/config.schema.yaml in rules/common.smk (errors name the key and the file)
include: "rules/common.smk"
include: "rules/load.smk"
include: "rules/crop.smk"
include: "rules/sync.smk"
include: "rules/calibrate.smk"
include: "rules/align.smk"
include: "rules/metrics.smk"
include: "rules/drift.smk"
include: "rules/consistency.smk"
include: "rules/efficiency.smk"
include: "rules/tables.smk"
include: "rules/report.smk"


rule all:
    input:
        rules.tables.output,
        rules.figures.output,
        expand(manifest("report"), batch=BATCHES),
    default_target: True


onsuccess:
    failures = epa_tables.failure_report(f"{RESULTS}/summary.csv")
    if failures:
        print(failures)
