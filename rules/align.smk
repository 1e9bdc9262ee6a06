# Step 3: world-frame alignment.
rule align:
    input:
        pairs=f"{CASE}/04_calibrate/pairs.csv",
        calibrate=f"{CASE}/04_calibrate/calibrate.json",
    output:
        pairs=f"{CASE}/05_align/pairs.csv",
        aligned=f"{CASE}/05_align/aligned.tum",
        transform=f"{CASE}/05_align/transform.json",
    params:
        cfg={"mode": EPA["mode"], "align": EPA["align"]},
        version=EPA_VERSION,
    log:
        f"{CASE}/logs/align.log",
    conda:
        "../envs/epica.yaml"
    script:
        "../scripts/align.py"
