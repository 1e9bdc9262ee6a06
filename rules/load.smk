# Load: read the reference and the estimate in any supported format: 01_load/.
rule load:
    input:
        sources=lambda wc: batch_sources(wc.batch),
    output:
        manifest=manifest("load"),
    params:
        **stage_params("load"),
    log:
        batch_log("load"),
    benchmark:
        batch_benchmark("load")
    threads: 1
    resources:
        **STAGE_RESOURCES,
    run:
        run_stage("load", params, output, log)
