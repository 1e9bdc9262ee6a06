# ATE, distance and time RPE, drift rate; per-pose and per-pair errors: 06_metrics/.
rule metrics:
    input:
        upstream=manifest("align"),
    output:
        manifest=manifest("metrics"),
    params:
        **stage_params("metrics"),
    log:
        batch_log("metrics"),
    benchmark:
        batch_benchmark("metrics")
    threads: 1
    resources:
        **STAGE_RESOURCES,
    run:
        run_stage("metrics", params, output, log, input.upstream)
