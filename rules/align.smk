# Step 3: world-frame alignment: 05_align/.
rule align:
    input:
        upstream=manifest("calibrate"),
    output:
        manifest=manifest("align"),
    params:
        **stage_params("align"),
    log:
        batch_log("align"),
    benchmark:
        batch_benchmark("align")
    threads: 1
    resources:
        **STAGE_RESOURCES,
    run:
        run_stage("align", params, output, log, input.upstream)
