# The stage rules, generated once from the stage list (epa.workflow.chain.STAGES): each runs one
# stage for one batch of cases and declares only its batch manifest (every case's artifacts are
# under results/cases/). The job body is epa.workflow.jobs.run_job, a plain function.
# No benchmark directive: for one, Snakemake samples the memory of its whole process tree (reading
# /proc/*/smaps), 7 of the example's 9 s of system time; run_job writes the job's wall and CPU
# seconds to the same file instead.
for stage_name in epa_chain.NAMES:

    rule:
        name:
            stage_name
        input:
            **stage_input(stage_name),
        output:
            manifest=manifest(stage_name),
        log:
            batch_log(stage_name),
        threads: 1
        resources:
            **STAGE_RESOURCES,
        params:
            **stage_params(stage_name),
            stage=stage_name,
        run:
            epa_jobs.run_job(**stage_job(params, input, output, log, wildcards))
