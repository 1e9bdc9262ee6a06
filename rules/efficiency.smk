# per-frame timing: runtime statistics and EA-Drift: 09_efficiency/ ("available": false without timing).
rule efficiency:
    input:
        upstream=manifest("consistency"),
    output:
        manifest=manifest("efficiency"),
    params:
        **stage_params("efficiency"),
    log:
        batch_log("efficiency"),
    benchmark:
        batch_benchmark("efficiency")
    threads: 1
    resources:
        **STAGE_RESOURCES,
    run:
        run_stage("efficiency", params, output, log, input.upstream)
