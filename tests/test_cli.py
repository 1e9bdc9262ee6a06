import json
import subprocess
import sys

import bag_fixture
import pytest

from epa.cli import main as cli


def test_eval_writes_metrics_json(tmp_path):
    from epa import simulate

    simulate.simulate(tmp_path / "sim")
    out = tmp_path / "out"
    assert (
        cli.main(
            [
                "eval",
                str(tmp_path / "sim/truth/drone_figure8.txt"),
                str(tmp_path / "sim/algorithms/vio_camera/drone_figure8/run1.csv"),
                "--out",
                str(out),
            ]
        )
        == 0
    )
    m = json.load(open(out / "06_metrics/metrics.json"))
    assert {
        "n_matched",
        "alignment",
        "ate",
        "rpe_distance",
        "rpe_time_1s",
        "drift_rate_pct",
    } <= set(m)
    assert set(m["rpe_distance"]) == {"8", "16", "24", "32", "40", "48"}
    assert abs(m["time_offset_s"] - 0.05) < 0.005 and m["eval_source"] == "epa"


def test_bad_input_exits_nonzero_with_one_line(tmp_path):
    bad = tmp_path / "bad.txt"
    bad.write_text("1 2 3\n")
    r = subprocess.run(
        [
            sys.executable,
            "-m",
            "epa.cli.main",
            "eval",
            str(bad),
            str(bad),
            "--out",
            str(tmp_path / "o"),
        ],
        capture_output=True,
        text=True,
    )
    assert (
        r.returncode == 2
        and r.stderr.count("\n") == 1
        and "bad.txt" in r.stderr
        and "Traceback" not in r.stderr
    )
    assert not (tmp_path / "o" / "06_metrics").exists()


def test_traj_lists_a_bags_topics_and_exports_one(tmp_path, capsys):
    import numpy as np

    from epa.core.trajectory import Trajectory
    from epa.readers import text

    t = 1_700_000_000 + np.arange(50) * 0.1
    traj = Trajectory(
        t, np.column_stack([t - t[0], np.zeros(50), np.zeros(50)]), np.tile([0, 0, 0, 1.0], (50, 1))
    )
    bag_fixture.write_bag(
        tmp_path / "b.bag",
        {"/odom": ("nav_msgs/msg/Odometry", traj), "/tf": ("tf2_msgs/msg/TFMessage", traj)},
        frames=("map", "base"),
    )
    assert cli.main(["traj", str(tmp_path / "b.bag")]) == 0
    listing = capsys.readouterr().out
    assert "2 topics" in listing
    assert (
        "/odom  nav_msgs/msg/Odometry" in listing
        and "50 msgs      4.900 s  1700000000.000000" in listing
    )
    assert (
        cli.main(
            [
                "traj",
                str(tmp_path / "b.bag"),
                "--topic",
                "/tf",
                "--frames",
                "map",
                "base",
                "--export",
                str(tmp_path / "tf.tum"),
            ]
        )
        == 0
    )
    shown = capsys.readouterr().out
    assert "bag TF map -> base (50 poses of /tf, header stamps)" in shown
    assert "50 poses, 4.900 s" in shown and "10.00 Hz, path length 4.900 m" in shown
    back = text.read_trajectory(tmp_path / "tf.tum")
    np.testing.assert_array_equal(back.t, traj.t) and np.testing.assert_array_equal(back.p, traj.p)
    # a text file: what it was read as, and its numbers
    assert cli.main(["traj", str(tmp_path / "tf.tum")]) == 0
    assert "format csv (8 columns, header names them)" in capsys.readouterr().out
    assert (
        cli.main(
            [
                "traj",
                str(tmp_path / "b.bag"),
                "--topic",
                "/odom",
                "--export",
                str(tmp_path / "x.kitti"),
            ]
        )
        == 2
    )
    assert "x.kitti: export to .txt or .tum (TUM) or .csv" in capsys.readouterr().err


def test_a_ros2_bag_folder_is_a_run(tmp_path):
    import numpy as np

    from epa.core.trajectory import Trajectory
    from epa.workflow import discovery as cases

    t = np.arange(20) * 0.1
    traj = Trajectory(t, np.zeros((20, 3)), np.tile([0, 0, 0, 1.0], (20, 1)))
    (tmp_path / "truth").mkdir()
    (tmp_path / "truth/seq.txt").write_text("1 0 0 0 0 0 0 1\n")
    (tmp_path / "algs/a/seq").mkdir(parents=True)
    bag_fixture.write_bag(
        tmp_path / "algs/a/seq/run1",
        {"/p": ("geometry_msgs/msg/PoseStamped", traj)},
        storage="mcap",
    )
    (tmp_path / "algs/a/seq/run1_timing.txt").write_text("0 12\n")
    _, found = cases.discover(tmp_path / "truth", tmp_path / "algs")
    assert [(c.key, c.estimate.name) for c in found] == [("a/seq/run1", "run1")]


def test_config_lists_defaults_and_marks_what_a_config_sets(tmp_path, capsys, caplog):
    from epa.cli import main as cli

    assert cli.main(["config"]) == 0
    defaults = capsys.readouterr().out.splitlines()
    assert "sync.max_diff: null" in defaults and "metrics.kitti: false" in defaults
    (tmp_path / "c.yaml").write_text(
        "truth_dir: t\nalgorithms_dir: a\nmetrics: {kitti: true}\nmode: ov_eval\n"
        "sync: {max_diff: 0.05}\n"
    )
    assert cli.main(["config", str(tmp_path / "c.yaml")]) == 0
    captured = capsys.readouterr()
    lines = captured.out.splitlines()
    assert "metrics.kitti: true  # set (default false)" in lines
    # ov_eval's value: the mode overrides the file
    assert "sync.max_diff: 0.02  # set (default null)" in lines
    assert "mode ov_eval overrides sync.max_diff: 0.05 -> 0.02" in caplog.text
    assert cli.main(["config", str(tmp_path / "missing.yaml")]) == 2


def test_epica_is_the_same_command():
    import importlib.metadata

    scripts = {e.name: e.value for e in importlib.metadata.entry_points(group="console_scripts")}
    assert scripts["epica"] == scripts["epa"] == "epa.cli.main:main"


def _eval_imports(tmp_path, prelude: str = "") -> str:
    """What `epa eval` of the example's two small text files without a report imports: its exit
    status, the heavy modules and the other commands' modules, after ``prelude``."""
    from pathlib import Path

    example = Path(__file__).resolve().parents[1] / "example"
    code = (
        "import sys\n"
        "from epa.cli import main\n"
        f"{prelude}"
        f"status = main.main(['eval', {str(example / 'truth/drone_figure8.txt')!r},"
        f" {str(example / 'algorithms/vio_camera/drone_figure8/run1.csv')!r},"
        f" '--out', {str(tmp_path / 'out')!r}])\n"
        "heavy = ('matplotlib', 'pandas', 'scipy', 'rosbags', 'jsonschema', 'pyarrow', 'yaml',"
        " 'email')\n"
        "others = ('epa.evo.commands', 'epa.rpg.command', 'epa.workflow.verify', 'epa.readers.bags')\n"
        "print(status, sorted({n.split('.')[0] for n in sys.modules if n.split('.')[0] in heavy}),"
        " sorted(n for n in sys.modules if n in others))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    return out.stdout.strip().splitlines()[-1]


def test_eval_imports_only_what_its_path_needs(tmp_path):
    """`epa eval` of two small text files without a report: no matplotlib, pandas nor pyarrow (files
    under the C parsers' sizes), scipy, rosbags, nor jsonschema (the defaults need no validator), nor
    PyYAML (the schema is read from its JSON, the resolved config written without it) or
    importlib.metadata (the package versions are read from their dist-info folders), and none of the
    other commands' modules."""
    assert _eval_imports(tmp_path) == "0 [] []"


def test_ape_imports_only_what_its_path_needs():
    """`epa ape` builds only its own parser: neither eval's module nor the metric registry that its
    --protocol choices import (every metric module), no other command's modules, and no bag reader
    for two text files; it prints the same statistics block."""
    from pathlib import Path

    example = Path(__file__).resolve().parents[1] / "example"
    ref = example / "truth/drone_figure8.txt"
    est = example / "algorithms/vo_drifty/drone_figure8/run1.txt"
    code = (
        "import sys\n"
        "from epa.cli import main\n"
        f"status = main.main(['ape', 'tum', {str(ref)!r}, {str(est)!r}, '-a'])\n"
        "others = ('epa.cli.evaluate', 'epa.metrics.registry', 'epa.metrics.eth3d', 'epa.rpg.command',"
        " 'epa.cli.tools', 'epa.readers.bags', 'epa.workflow.chain')\n"
        "print(status, sorted(n for n in sys.modules if n in others))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    lines = out.stdout.strip().splitlines()
    assert lines[-1] == "0 []"
    assert lines[0] == "APE w.r.t. translation part (m)" and "rmse" in out.stdout


def test_a_commands_own_parser_keeps_the_top_level_usage(capsys):
    """A command builds only its own parser, yet an error the top level reports (an unrecognised
    argument) prints the usage line it always printed: epica's own commands after one of them,
    every command after another."""
    own = "{eval,traj,fig,config,selftest,stage,simulate}"
    every = (
        "{eval,traj,fig,config,ape,rpe,res,rpg,verify,pack,tum-ate,tum-rpe,selftest,stage,simulate}"
    )
    for argv, listed in ((["config", "--bogus"], own), (["res", "x.zip", "--bogus"], every)):
        with pytest.raises(SystemExit) as stop:
            cli.main(argv)
        err = capsys.readouterr().err
        assert stop.value.code == 2 and "unrecognized arguments: --bogus" in err
        assert " ".join(err.split()).startswith(f"usage: epa [-h] [--version] {listed} ...")


def test_eval_of_large_files_reads_them_without_pandas(tmp_path):
    """Files large enough for a parser in C (here: every size is) are read by pyarrow's reader where
    it is installed, the TUM file and the CSV alike: pandas (0.2-0.35 s to import) is not imported."""
    pytest.importorskip("pyarrow")
    prelude = "from epa.readers import text\ntext.ARROW_MIN_BYTES = text.C_PARSER_MIN_BYTES = 0\n"
    assert _eval_imports(tmp_path, prelude) == "0 ['pyarrow'] []"


def test_a_config_at_its_defaults_is_valid_without_the_validator():
    """settings.resolve skips jsonschema only for what it can tell is valid: every setting at its
    default (same type), a plain boolean, a grid folder; the rest, valid or not, goes to jsonschema."""
    import jsonschema
    import pytest

    from epa.core.errors import EpaError
    from epa.workflow import settings

    validator = jsonschema.Draft202012Validator(settings.schema())
    plain = [
        {"truth_dir": ".", "algorithms_dir": "."},
        {"truth_dir": "t", "algorithms_dir": "a", "report": {"per_case": False}},
        {"truth_dir": "t", "algorithms_dir": "a", "sync": {"offset": 0.0}, "mode": "epa"},
    ]
    for cfg in plain:
        assert settings._plainly_valid(cfg, settings.schema()) and validator.is_valid(cfg)
    told_apart = [
        {"truth_dir": ".", "algorithms_dir": "", "mode": "epa"},  # an empty folder
        {"truth_dir": ".", "algorithms_dir": ".", "sync": {"max_diff": -1.0}},  # out of bounds
        {"truth_dir": ".", "algorithms_dir": ".", "sync": {"max_diff": 0.05}},  # valid, not default
        {"truth_dir": ".", "algorithms_dir": ".", "grid": {"max_batches": 8.0}},  # float for an int
        {"truth_dir": ".", "algorithms_dir": ".", "typo": 1},  # an unknown key
        {"truth_dir": ".", "algorithms_dir": ".", "mode": "ov_eval"},  # valid, not default
    ]
    for cfg in told_apart:
        assert not settings._plainly_valid(cfg, settings.schema())
    with pytest.raises(EpaError, match="max_diff"):
        settings.resolve(told_apart[1])
    with pytest.raises(EpaError, match="typo"):
        settings.resolve(told_apart[4])
    # one folder without the other passes the schema (inputs may be named other ways) and is
    # refused by the inputs check after it
    with pytest.raises(EpaError, match="truth_dir without algorithms_dir"):
        settings.resolve({"truth_dir": "."})


def test_one_spelling_per_option_across_epas_own_commands(capsys):
    """Options of the same meaning are spelled alike (--config, --out), with hyphens; underscores
    only on the commands whose options copy another tool's (evo's, rpg's, the TUM scripts')."""
    import argparse

    top = cli._parser()
    sub = next(a for a in top._actions if isinstance(a, argparse._SubParsersAction))
    copies = {"ape", "rpe", "res", "rpg", "tum-ate", "tum-rpe"}
    shown = {
        name: {s for a in p._actions if a.help != argparse.SUPPRESS for s in a.option_strings}
        for name, p in sub.choices.items()
        if name not in copies
    }
    assert not {s for opts in shown.values() for s in opts if "_" in s}
    assert {"--config"} <= shown["eval"] & shown["selftest"] & shown["stage"]
    assert {"--out"} <= shown["eval"] & shown["fig"] & shown["pack"]
    assert not {"--configfile", "--output"} & {s for opts in shown.values() for s in opts}
    # the earlier spellings still work, with a warning
    args = top.parse_args(["pack", "results", "--output", "p.tar.gz"])
    assert args.out == "p.tar.gz"
    assert capsys.readouterr().err == "epa: WARNING: --output is deprecated: use --out\n"
    assert cli._parser().parse_args(["stage", "load", "case"]).config == "config/config.yaml"
    assert cli._parser().parse_args(["stage", "load", "case", "--configfile", "c.yaml"]).config == (
        "c.yaml"
    )
    assert "--configfile is deprecated: use --config" in capsys.readouterr().err
