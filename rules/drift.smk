# Local drift/fail detection, success rate and drift-valid metrics.
rule drift:
    input:
        ape=f"{CASE}/06_metrics/ape.csv",
        segments=f"{CASE}/06_metrics/rpe_segments.csv",
        time=f"{CASE}/06_metrics/rpe_time.csv",
    output:
        drift=f"{CASE}/07_drift/drift.json",
        fail_segments=f"{CASE}/07_drift/fail_segments.csv",
        pose_valid=f"{CASE}/07_drift/pose_valid.csv",
        segments=f"{CASE}/07_drift/rpe_segments.csv",
        time=f"{CASE}/07_drift/rpe_time.csv",
    params:
        cfg={"drift": EPA["drift"], "metrics": EPA["metrics"]},
        version=EPA_VERSION,
    log:
        f"{CASE}/logs/drift.log",
    conda:
        "../envs/epica.yaml"
    script:
        "../scripts/drift.py"
