# Step 2 (sensor-to-body extrinsic) and the evaluation plan (the ov_eval fallback): 04_calibrate/.
rule calibrate:
    input:
        upstream=manifest("sync"),
    output:
        manifest=manifest("calibrate"),
    params:
        **stage_params("calibrate"),
    log:
        batch_log("calibrate"),
    benchmark:
        batch_benchmark("calibrate")
    threads: 1
    resources:
        **STAGE_RESOURCES,
    run:
        run_stage("calibrate", params, output, log, input.upstream)
