# Per case, from the artifacts: metrics.json, metrics_summary.csv, report_en.md / report_zh.md,
# figures/*.png (+ bundles for `epa fig`), <run>.zip: 10_report/. matplotlib is imported only here.
rule report:
    input:
        upstream=manifest("efficiency"),
    output:
        manifest=manifest("report"),
    params:
        **stage_params("report"),
    log:
        batch_log("report"),
    benchmark:
        batch_benchmark("report")
    threads: 1
    resources:
        **STAGE_RESOURCES,
    run:
        run_stage("report", params, output, log, input.upstream)


# The grid's figures, from summary.csv and results/consistency/: vector PDF beside PNG.
rule figures:
    input:
        summary=rules.tables.output.summary,
        across_runs=rules.tables.output.across_runs,
        success_curves=rules.tables.output.success_curves,
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
    params:
        segments=EPA["metrics"]["segments"],
        version=EPA_VERSION,
    log:
        f"{RESULTS}/logs/figures.log",
    benchmark:
        f"{RESULTS}/benchmarks/figures.tsv"
    threads: 1
    resources:
        mem_mb=1500,
        runtime=5,
    run:
        make_grid_figures(params, log)
