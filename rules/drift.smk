# Drift/fail detection, success rate, drift-valid metrics: 07_drift/.
rule drift:
    input:
        upstream=manifest("metrics"),
    output:
        manifest=manifest("drift"),
    params:
        **stage_params("drift"),
    log:
        batch_log("drift"),
    benchmark:
        batch_benchmark("drift")
    threads: 1
    resources:
        **STAGE_RESOURCES,
    run:
        run_stage("drift", params, output, log, input.upstream)
