# The grid's figures, from summary.csv and results/consistency/: vector PDF beside PNG
# (scripts/figures.py, which also runs on its own).
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
    log:
        f"{RESULTS}/logs/figures.log",
    benchmark:
        f"{RESULTS}/benchmarks/figures.tsv"
    conda:
        "../envs/epica.yaml"
    threads: 2
    resources:
        mem_mb=1500,
        runtime=5,
    params:
        results=lambda wc, input: os.path.dirname(input.summary),
        version=EPA_VERSION,
    script:
        "../scripts/figures.py"
