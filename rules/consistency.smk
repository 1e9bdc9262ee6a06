# NEES and ±3σ bounds of the estimate's own covariance: 08_consistency/ ("available": false without covariance).
rule consistency:
    input:
        upstream=manifest("drift"),
    output:
        manifest=manifest("consistency"),
    params:
        **stage_params("consistency"),
    log:
        batch_log("consistency"),
    benchmark:
        batch_benchmark("consistency")
    threads: 1
    resources:
        **STAGE_RESOURCES,
    run:
        run_stage("consistency", params, output, log, input.upstream)
