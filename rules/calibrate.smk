# Step 2: sensor-to-body extrinsic (hand-eye), or the ov_eval fallback.
rule calibrate:
    input:
        pairs=f"{CASE}/03_sync/pairs.csv",
        sync=f"{CASE}/03_sync/sync.json",
    output:
        pairs=f"{CASE}/04_calibrate/pairs.csv",
        info=f"{CASE}/04_calibrate/calibrate.json",
    params:
        cfg={"mode": EPA["mode"], "sync": EPA["sync"], "calibrate": EPA["calibrate"]},
        version=EPA_VERSION,
    log:
        f"{CASE}/logs/calibrate.log",
    conda:
        "../envs/epica.yaml"
    script:
        "../scripts/calibrate.py"
