rule metrics:
    input:
        pairs=CASE + "/05_align/pairs.csv",
        transform=CASE + "/05_align/transform.json",
        sync=CASE + "/03_sync/sync.json",
        calibrate=CASE + "/04_calibrate/calibrate.json",
    output:
        metrics=CASE + "/06_metrics/metrics.json",
        ape=CASE + "/06_metrics/ape.csv",
        segments=CASE + "/06_metrics/rpe_segments.csv",
        time=CASE + "/06_metrics/rpe_time.csv",
    params:
        cfg={"metrics": EPA["metrics"]},
        version=EPA_VERSION,
    log:
        CASE + "/logs/metrics.log",
    conda:
        "../envs/epica.yaml"
    script:
        "../scripts/metrics.py"
