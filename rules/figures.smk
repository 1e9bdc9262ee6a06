# The grid's figures, from summary.csv and results/consistency/, and with per-case reports each
# dataset's trajectories and relative-error boxes from the reports' files: vector PDF beside PNG
# (scripts/figures.py's write, in the worker pool; the script also runs on its own).
from epa.outputs import dataset_figures as epa_dataset_figures

# (name, kind, dataset) of each per-dataset figure; none without per-case reports to draw from
PER_DATASET_FIGURES = (
    [
        (f"{kind}_{d}", kind, d)
        for d in sorted({c.dataset for c in CASES})
        for kind in epa_dataset_figures.PREFIXES
    ]
    if EPA["report"]["per_case"]
    else []
)


rule figures:
    input:
        summary=rules.tables.output.summary,
        across_runs=rules.tables.output.across_runs,
        success_curves=rules.tables.output.success_curves,
        # the per-dataset figures read the reports' files: none to wait for without them
        reports=(
            expand(manifest("report"), batch=BATCHES)
            if EPA["report"]["per_case"]
            else []
        ),
    output:
        **{
            f"{name}_{fmt}": report(
                f"{RESULTS}/figures/{name}.{fmt}",
                caption=f"../docs/captions/{name}.rst",
                category="Figures",
            )
            for name in epa_report.GRID_FIGURES
            for fmt in ("png", "pdf")
        },
        **{
            f"{name}_{fmt}": report(
                f"{RESULTS}/figures/{name}.{fmt}",
                caption=f"../docs/captions/{kind}.rst",
                category="Figures per dataset",
                subcategory=d,
            )
            for name, kind, d in PER_DATASET_FIGURES
            for fmt in ("png", "pdf")
        },
    log:
        f"{RESULTS}/logs/figures.log",
    threads: 2
    resources:
        mem_mb=1500,
        runtime=5,
    params:
        results=lambda wc, input: os.path.dirname(input.summary),
        per_dataset=EPA["report"]["per_case"],
        version=EPA_VERSION,
    run:
        grid_script(
            "figures",
            threads,
            results_dir=params.results,
            log_path=log[0],
            workers=threads,
            per_dataset=params.per_dataset,
        )
