# Step 1 (time offset by angular-speed cross-correlation), then association: 03_sync/.
rule sync:
    input:
        upstream=manifest("crop"),
    output:
        manifest=manifest("sync"),
    params:
        **stage_params("sync"),
    log:
        batch_log("sync"),
    benchmark:
        batch_benchmark("sync")
    threads: 1
    resources:
        **STAGE_RESOURCES,
    run:
        run_stage("sync", params, output, log, input.upstream)
