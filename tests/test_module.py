"""epica as another workflow's Snakemake module (README, docs/running.md): `module epica:
snakefile: ...; config: config["epica"]` and `use rule * from epica as epica_*` in a workflow of its
own folder run the bundled example to the golden tables, with epica's internal paths resolved from
its own Snakefile and its stage jobs in the Snakemake process's threads though epica's
profiles/default is not read there. One run of the example."""

import json
import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
GOLDEN = ROOT / "tests/golden/example"

HOST = f"""configfile: "config.yaml"


module epica:
    snakefile:
        "{ROOT / "Snakefile"}"
    config:
        config["epica"]


use rule * from epica as epica_*


rule all:
    default_target: True
    input:
        rules.epica_all.input,
"""
# the example's settings (config/config.yaml) under the host's key; per-case reports off: one run
CONFIG = f"""epica:
  truth_dir: {ROOT / "example/truth"}
  algorithms_dir: {ROOT / "example/algorithms"}
  results_dir: epica_results
  mode: epa
  sync: {{policy: ov_eval, estimate_offset: true, window: 2.0}}
  calibrate: {{enabled: true, pair_step: 1.0}}
  align: {{method: se3}}
  metrics: {{segments: [8, 16, 24, 32, 40, 48]}}
  drift: {{mode: fixed}}
  efficiency: {{sensor_rate_hz: 20}}
  report: {{per_case: false}}
"""


def test_a_host_workflow_runs_the_example_through_the_module(tmp_path):
    (tmp_path / "Snakefile").write_text(HOST)
    (tmp_path / "config.yaml").write_text(CONFIG)
    out = subprocess.run(
        [sys.executable, "-m", "snakemake", "--cores", "2", "--force-use-threads", "--verbose"],
        capture_output=True,
        text=True,
        cwd=tmp_path,  # no profile: the host's folder has none, and epica's is not read
    )
    log = out.stdout + out.stderr
    assert out.returncode == 0, log[-3000:]
    results = tmp_path / "epica_results"
    for name in ("summary.csv", "error_comparison.txt", "comparison.txt", "tables/ate.tex"):
        assert (results / name).read_text() == (GOLDEN / name).read_text(), name
    # a `run:` job Snakemake spawns into a new process says so at --verbose; none did
    assert "spawned job" not in log
    assert re.search(r"^(local)?rule (epica_)?load:$", log, re.M)  # 9.1.4 prints the module's name
    # the paper's captions and the provenance's checkout are epica's, not the host's folder
    assert (results / "paper/paper.tex").is_file()
    provenance = json.loads((results / "provenance.json").read_text())
    assert provenance["volatile"]["workflow_dir"] == str(ROOT)
