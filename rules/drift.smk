# Local drift/fail detection, success rate and drift-valid metrics.
rule drift:
    input:
        ape=CASE + "/06_metrics/ape.csv",
        segments=CASE + "/06_metrics/rpe_segments.csv",
        time=CASE + "/06_metrics/rpe_time.csv",
    output:
        drift=CASE + "/07_drift/drift.json",
        fail_segments=CASE + "/07_drift/fail_segments.csv",
        pose_valid=CASE + "/07_drift/pose_valid.csv",
        segments=CASE + "/07_drift/rpe_segments.csv",
        time=CASE + "/07_drift/rpe_time.csv",
    params:
        cfg={"drift": EPA["drift"], "metrics": EPA["metrics"]},
        version=EPA_VERSION,
    log:
        CASE + "/logs/drift.log",
    conda:
        "../envs/epica.yaml"
    script:
        "../scripts/drift.py"
