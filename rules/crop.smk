rule crop:
    input:
        ref=CASE + "/01_load/ref.tum",
        est=CASE + "/01_load/est.tum",
    output:
        ref=CASE + "/02_crop/ref.tum",
        est=CASE + "/02_crop/est.tum",
        info=CASE + "/02_crop/crop.json",
    params:
        cfg={"crop": EPA["crop"]},
        version=EPA_VERSION,
    log:
        CASE + "/logs/crop.log",
    conda:
        "../envs/epica.yaml"
    script:
        "../scripts/crop.py"
