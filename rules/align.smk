# Step 3: world-frame alignment.
rule align:
    input:
        pairs=CASE + "/04_calibrate/pairs.csv",
        calibrate=CASE + "/04_calibrate/calibrate.json",
    output:
        pairs=CASE + "/05_align/pairs.csv",
        aligned=CASE + "/05_align/aligned.tum",
        transform=CASE + "/05_align/transform.json",
    params:
        cfg={"mode": EPA["mode"], "align": EPA["align"]},
        version=EPA_VERSION,
    log:
        CASE + "/logs/align.log",
    conda:
        "../envs/epica.yaml"
    script:
        "../scripts/align.py"
