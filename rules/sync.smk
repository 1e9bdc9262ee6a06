# Step 1 (time offset by angular-speed cross-correlation) and association.
rule sync:
    input:
        ref=CASE + "/02_crop/ref.tum",
        est=CASE + "/02_crop/est.tum",
    output:
        pairs=CASE + "/03_sync/pairs.csv",
        info=CASE + "/03_sync/sync.json",
        xcorr=CASE + "/03_sync/xcorr.csv",
    params:
        cfg={"mode": EPA["mode"], "sync": EPA["sync"]},
        version=EPA_VERSION,
    log:
        CASE + "/logs/sync.log",
    conda:
        "../envs/epica.yaml"
    script:
        "../scripts/sync.py"
