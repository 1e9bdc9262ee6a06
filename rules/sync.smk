# Step 1 (time offset by angular-speed cross-correlation) and association.
rule sync:
    input:
        ref=f"{CASE}/02_crop/ref.tum",
        est=f"{CASE}/02_crop/est.tum",
    output:
        pairs=f"{CASE}/03_sync/pairs.csv",
        info=f"{CASE}/03_sync/sync.json",
        xcorr=f"{CASE}/03_sync/xcorr.csv",
    params:
        cfg={"mode": EPA["mode"], "sync": EPA["sync"]},
        version=EPA_VERSION,
    log:
        f"{CASE}/logs/sync.log",
    conda:
        "../envs/epica.yaml"
    script:
        "../scripts/sync.py"
