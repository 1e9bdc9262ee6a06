rule metrics:
    input:
        pairs=f"{CASE}/05_align/pairs.csv",
        transform=f"{CASE}/05_align/transform.json",
        sync=f"{CASE}/03_sync/sync.json",
        calibrate=f"{CASE}/04_calibrate/calibrate.json",
    output:
        metrics=f"{CASE}/06_metrics/metrics.json",
        ape=f"{CASE}/06_metrics/ape.csv",
        segments=f"{CASE}/06_metrics/rpe_segments.csv",
        time=f"{CASE}/06_metrics/rpe_time.csv",
    params:
        cfg={"metrics": EPA["metrics"]},
        version=EPA_VERSION,
    log:
        f"{CASE}/logs/metrics.log",
    conda:
        "../envs/epica.yaml"
    script:
        "../scripts/metrics.py"
