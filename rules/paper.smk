# results/paper/: every LaTeX table, every grid figure as PDF and paper.tex that \input's them
# (scripts/paper.py's write, in the worker pool; the script also runs on its own); compiles with
# `pdflatex paper.tex` there.
rule paper:
    input:
        tex=rules.tables.output.tex,
        comparison_tex=rules.tables.output.comparison_tex,
        figures=[f"{RESULTS}/figures/{name}.pdf" for name in epa_report.GRID_FIGURES],
        dataset_figures=[
            f"{RESULTS}/figures/{name}.pdf" for name, _, _ in PER_DATASET_FIGURES
        ],
    output:
        tex=report(
            f"{RESULTS}/paper/paper.tex",
            caption="../docs/captions/paper.rst",
            category="Paper",
        ),
        tables=[
            f"{RESULTS}/paper/tables/{name}.tex"
            for name in epa_tables.table_names(EPA) + ("comparison",)
        ],
        figures=[
            f"{RESULTS}/paper/figures/{name}.pdf" for name in epa_report.GRID_FIGURES
        ],
        dataset_figures=[
            f"{RESULTS}/paper/figures/{name}.pdf" for name, _, _ in PER_DATASET_FIGURES
        ],
    log:
        f"{RESULTS}/logs/paper.log",
    threads: 1
    resources:
        mem_mb=500,
        runtime=2,
    params:
        results=lambda wc, input: os.path.dirname(input.comparison_tex),
        captions=os.path.join(EPICA_DIR, "docs", "captions"),
        version=EPA_VERSION,
    run:
        grid_script(
            "paper",
            threads,
            results_dir=params.results,
            caption_dir=params.captions,
            log_path=log[0],
        )
