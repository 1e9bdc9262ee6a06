# epica: algorithm x dataset x run grid -> error_comparison tables. See README.md.
from snakemake.utils import min_version

min_version("9.1.4")  # and below 10: pyproject.toml


configfile: "config/config.yaml"


# validated against src/epa/workflow/config.schema.yaml in rules/common.smk (errors name the key and the file)
include: "rules/common.smk"
include: "rules/stages.smk"
include: "rules/tables.smk"
include: "rules/figures.smk"
include: "rules/paper.smk"


rule all:
    default_target: True
    input:
        rules.tables.output,
        rules.provenance.output,
        rules.figures.output,
        rules.paper.output,
        expand(manifest(epa_chain.NAMES[-1]), batch=BATCHES),  # the last stage


onsuccess:
    quick_exit()
    if os.path.exists(
        f"{RESULTS}/summary.csv"
    ):  # not after a run of some stages only
        print(epa_paper.where_lines(RESULTS, EPA["report"]["per_case"]))
        failures = epa_tables.failure_report(f"{RESULTS}/summary.csv")
        print(
            failures or f"epica: every case has a result ({len(CASE_BY_KEY)} cases)"
        )


onerror:
    quick_exit()
