rule tables:
    input:
        load=case_files(f"{CASE}/01_load/load.json"),
        metrics=case_files(f"{CASE}/06_metrics/metrics.json"),
        drift=case_files(f"{CASE}/07_drift/drift.json"),
        segments=case_files(f"{CASE}/07_drift/rpe_segments.csv"),
        time=case_files(f"{CASE}/07_drift/rpe_time.csv"),
    output:
        text=report(f"{RESULTS}/error_comparison.txt", caption="../docs/report_caption.rst", category="Tables"),
        summary=report(f"{RESULTS}/summary.csv", caption="../docs/report_caption.rst", category="Tables"),
        tex=[f"{RESULTS}/tables/{name}.tex" for name in TABLE_NAMES],
    params:
        cases=[[c.algorithm, c.dataset, c.run] for c in CASES],
        cfg={"tables": EPA["tables"], "metrics": EPA["metrics"]},
        version=EPA_VERSION,
    log:
        f"{RESULTS}/logs/tables.log",
    conda:
        "../envs/epica.yaml"
    script:
        "../scripts/tables.py"
