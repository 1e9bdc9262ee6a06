rule load:
    input:
        truth=lambda wc: str(TRUTH[wc.dataset]),
        estimate=lambda wc: ESTIMATES[f"{wc.algorithm}/{wc.dataset}/{wc.run}"],
    output:
        ref=f"{CASE}/01_load/ref.tum",
        est=f"{CASE}/01_load/est.tum",
        info=f"{CASE}/01_load/load.json",
    params:
        cfg={"load": EPA["load"]},
        version=EPA_VERSION,
    log:
        f"{CASE}/logs/load.log",
    conda:
        "../envs/epica.yaml"
    script:
        "../scripts/load.py"
