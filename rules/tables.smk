# error_comparison.txt, one .tex and .csv per LaTeX table, cells.csv, summary.csv, comparison,
# results/consistency/: every case, failed ones marked; mode rpg: rpg's summary tables too
# (scripts/tables.py's write, in the worker pool; the script also runs on its own). Its params hold
# only the settings the tables read: another section's change re-runs the stages that read it, and
# provenance below, not the tables, figures and paper.
rule tables:
    input:
        expand(manifest("efficiency"), batch=BATCHES),
        idle_truths=lambda wc: list(idle_truths().values()),
    output:
        text=report(
            f"{RESULTS}/error_comparison.txt",
            caption="../docs/report_caption.rst",
            category="Tables",
        ),
        summary=report(
            f"{RESULTS}/summary.csv",
            caption="../docs/report_caption.rst",
            category="Tables",
        ),
        tex=[f"{RESULTS}/tables/{name}.tex" for name in epa_tables.table_names(EPA)],
        csv=[f"{RESULTS}/tables/{name}.csv" for name in epa_tables.cell_tables(EPA)],
        cells=f"{RESULTS}/cells.csv",
        mode_files=[f"{RESULTS}/{name}" for name in epa_tables.mode_files(EPA)],
        across_runs=f"{RESULTS}/consistency/summary.csv",
        comparison=report(
            f"{RESULTS}/comparison.txt",
            caption="../docs/report_caption.rst",
            category="Tables",
        ),
        comparison_tex=f"{RESULTS}/comparison.tex",
        success_curves=f"{RESULTS}/success_curves.csv",
    log:
        f"{RESULTS}/logs/tables.log",
    threads: 2
    resources:
        mem_mb=lambda wc: 1000 + len(CASE_BY_KEY) // 10,
        runtime=lambda wc: 2 + len(CASE_BY_KEY) // 2000,
    params:
        cases=lambda wc: sorted(CASE_BY_KEY),  # a function: braces in a name are not wildcards
        idle_truths=lambda wc: idle_truths(),
        results=lambda wc, output: os.path.dirname(output.summary),
        # the tables' sections and those the registered metrics declare (their settings)
        settings=epa_chain.tables_settings(EPA),
        version=EPA_VERSION,
    run:
        grid_script(
            "tables",
            threads,
            cases=params.cases,
            results_dir=params.results,
            settings=params.settings,
            idle_truths=params.idle_truths,
            log_path=log[0],
            workers=threads,
        )


# provenance.json and config.resolved.yaml: what made the results (the whole resolved config, every
# input file hashed after the tables, the checkout). Its own rule, so that a setting only some
# stages read (report:) re-writes these two files and not the tables. In this process (run:).
rule provenance:
    input:
        rules.tables.output.summary,  # after the tables, and again whenever they change
    output:
        provenance=report(
            f"{RESULTS}/provenance.json",
            caption="../docs/captions/provenance.rst",
            category="Provenance",
        ),
        config_resolved=report(
            f"{RESULTS}/config.resolved.yaml",
            caption="../docs/captions/provenance.rst",
            category="Provenance",
        ),
    log:
        f"{RESULTS}/logs/provenance.log",
    threads: 1
    resources:
        mem_mb=500,
        runtime=lambda wc: 2 + len(CASE_BY_KEY) // 2000,
    params:
        resolved=EPA,
        inputs=lambda wc: epa_provenance.grid_inputs(EPA, CASES, idle_truths()),
        workflow_dir=EPICA_DIR,
        version=EPA_VERSION,
    run:
        write_provenance(params, output, log)
