rule crop:
    input:
        ref=f"{CASE}/01_load/ref.tum",
        est=f"{CASE}/01_load/est.tum",
    output:
        ref=f"{CASE}/02_crop/ref.tum",
        est=f"{CASE}/02_crop/est.tum",
        info=f"{CASE}/02_crop/crop.json",
    params:
        cfg={"crop": EPA["crop"]},
        version=EPA_VERSION,
    log:
        f"{CASE}/logs/crop.log",
    conda:
        "../envs/epica.yaml"
    script:
        "../scripts/crop.py"
