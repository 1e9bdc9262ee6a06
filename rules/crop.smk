# Crop: the configured time window (crop.start/end, crop.skip_first).
rule crop:
    input:
        upstream=manifest("load"),
    output:
        manifest=manifest("crop"),
    params:
        **stage_params("crop"),
    log:
        batch_log("crop"),
    benchmark:
        batch_benchmark("crop")
    threads: 1
    resources:
        **STAGE_RESOURCES,
    run:
        run_stage("crop", params, output, log, input.upstream)
