import json
import subprocess
import sys

from epa import cli


def test_eval_writes_metrics_json(tmp_path):
    from epa import simulate

    simulate.simulate(tmp_path / "sim")
    out = tmp_path / "out"
    assert cli.main(["eval", str(tmp_path / "sim/truth/drone_figure8.txt"),
                     str(tmp_path / "sim/algorithms/vio_camera/drone_figure8/run1.csv"), "--out", str(out)]) == 0
    m = json.load(open(out / "06_metrics/metrics.json"))
    assert {"n_matched", "alignment", "ate", "rpe_distance", "rpe_time_1s", "drift_rate_pct"} <= set(m)
    assert set(m["rpe_distance"]) == {"8", "16", "24", "32", "40", "48"}
    assert abs(m["time_offset_s"] - 0.05) < 0.005 and m["eval_source"] == "epa"


def test_bad_input_exits_nonzero_with_one_line(tmp_path):
    bad = tmp_path / "bad.txt"
    bad.write_text("1 2 3\n")
    r = subprocess.run([sys.executable, "-m", "epa.cli", "eval", str(bad), str(bad), "--out", str(tmp_path / "o")],
                       capture_output=True, text=True)
    assert r.returncode == 2 and r.stderr.count("\n") == 1 and "bad.txt" in r.stderr and "Traceback" not in r.stderr
    assert not (tmp_path / "o" / "06_metrics").exists()
