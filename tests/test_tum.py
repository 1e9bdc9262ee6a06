"""The TUM RGB-D benchmark's scripts: ``epa tum-ate`` / ``epa tum-rpe`` print what ``evaluate_ate.py``
and ``evaluate_rpe.py`` print (tests/oracles/tum/, made by the real scripts on TUM fr1/xyz), the
metric's record from ``epa eval --protocol tum`` and from a grid has the same numbers, and the pieces
(association, closest-stamp search, random pairs, 4x4 arithmetic) are the scripts' own rules."""

import json
import math
import random
import shutil

import numpy as np
import pytest
from conftest import DATA, ROOT

from epa.cli import main as cli
from epa.core.errors import EpaError
from epa.metrics import registry, tum
from epa.readers import tum_script

ORACLES = ROOT / "tests" / "oracles" / "tum"
TUM = DATA / "MichaelGrupp_evo" / "test" / "data"
EUROC = DATA / "rpng_open_vins" / "ov_data" / "euroc_mav"
RPG = DATA / "uzh-rpg_rpg_trajectory_evaluation" / "results"
FILES = {
    "gt": TUM / "freiburg1_xyz-groundtruth.txt",
    "rgbdslam": TUM / "freiburg1_xyz-rgbdslam.txt",
    "orb": TUM / "freiburg1_xyz-ORB_kf_mono.txt",
    "mh01": EUROC / "MH_01_easy.txt",
    "mh03": EUROC / "MH_03_medium.txt",
    "mh01_vio_mono": RPG
    / "euroc_mono_stereo/laptop/vio_mono/laptop_vio_mono_MH_01/stamped_traj_estimate.txt",
    "mh03_ba3": RPG
    / "euroc_vislam_mono/laptop/vislam_ba/laptop_vislam_ba_MH_03/stamped_ba_estimate3.txt",
}
needs_data = pytest.mark.skipif(not TUM.is_dir(), reason=f"no shared data at {TUM}")
# The mean alone that evaluate_rpe.py prints is a float's repr (17 digits), so it shows the last bit
# of the 4x4 products and inverses, which differs between BLAS kernels: the scripts ran under Python
# 2.7 with numpy 1.16.6, 7e-18 m from epica (0.018645129350051033 against ...026); the Python 3 port
# on this machine's numpy 2.4.6 gives epica's digits exactly on the default CPU path, and 3e-18 m
# apart on the restricted one (NPY_DISABLE_CPU_FEATURES, OPENBLAS_CORETYPE=Sandybridge). Every %f
# output is compared as text.
REPR_TOL_M = 1e-15


def _cases() -> list[tuple[str, str, str, list[str]]]:
    rows = []
    for line in (ORACLES / "cases.txt").read_text().splitlines():
        if line and not line.startswith("#"):
            name, python, script, *args = line.split()
            rows.append((name, python, script, args))
    return rows


def _run(capsys, script, args, python, save_dir) -> str:
    argv = [a.format(save=save_dir, **FILES) for a in args]
    if script == "rpe" and python == "3":
        argv.append("--sampler=python3")
    assert cli.main([f"tum-{script}", *argv]) == 0
    return capsys.readouterr().out


@needs_data
@pytest.mark.parametrize(("name", "python", "script", "args"), _cases(), ids=lambda v: str(v))
def test_the_commands_print_what_the_scripts_print(capsys, tmp_path, name, python, script, args):
    ours = _run(capsys, script, args, python, tmp_path)
    theirs = (ORACLES / name).read_text()
    if script == "rpe" and "--verbose" not in args:
        assert ours.count("\n") == theirs.count("\n") == 1
        assert abs(float(ours) - float(theirs)) <= REPR_TOL_M, (ours, theirs)
    else:
        assert ours == theirs
    for (
        saved
    ) in tmp_path.iterdir():  # --save, --save_associations: the script's file, byte for byte
        assert saved.read_bytes() == (ORACLES / saved.name).read_bytes(), saved.name


def _printed(name: str) -> dict:
    lines = (ORACLES / name).read_text().split("\n")
    return {ln.split()[0]: float(ln.split()[1]) for ln in lines if ln}


@needs_data
def test_the_protocol_record_has_the_printed_numbers(tmp_path, capsys):
    out = tmp_path / "case"
    assert (
        cli.main(
            [
                "eval",
                str(FILES["gt"]),
                str(FILES["rgbdslam"]),
                "--out",
                str(out),
                "--protocol",
                "tum",
            ]
        )
        == 0
    )
    record = json.loads((out / "06_metrics" / "metrics.json").read_text())["tum"]
    _agree(record, "ate_rgbdslam_verbose.txt", "rpe_rgbdslam_verbose.txt")


def _agree(record: dict, ate_name: str, rpe_name: str) -> None:
    """The record against the script's printed 6 decimals (half a unit of the last: 5e-7)."""
    ate, rpe = _printed(ate_name), _printed(rpe_name)
    assert record["ate"]["pairs"] == ate["compared_pose_pairs"]
    assert record["rpe"]["pairs"] == rpe["compared_pose_pairs"]
    for k in tum.STATISTICS:
        assert abs(record["ate"]["trans_m"][k] - ate[f"absolute_translational_error.{k}"]) <= 5e-7
        assert abs(record["rpe"]["trans_m"][k] - rpe[f"translational_error.{k}"]) <= 5e-7
        printed = rpe[f"rotational_error.{k}"]
        if k == "median":  # the script prints the median in rad under "deg"
            printed = math.degrees(printed)
        assert abs(record["rpe"]["rot_deg"][k] - printed) <= 5e-7 * (57.3 if k == "median" else 1)


@needs_data
def test_a_grid_with_metrics_tum_on_gives_the_record_table_and_columns(tmp_path):
    from conftest import run_stages

    from epa.outputs import tables
    from epa.workflow import chain, settings

    for name in ("truth", "algs/orb/fr1_xyz"):
        (tmp_path / name).mkdir(parents=True)
    shutil.copy(FILES["gt"], tmp_path / "truth" / "fr1_xyz.txt")
    shutil.copy(FILES["rgbdslam"], tmp_path / "algs" / "orb" / "fr1_xyz" / "run1.txt")
    cfg = settings.resolve(
        {
            "truth_dir": str(tmp_path / "truth"),
            "algorithms_dir": str(tmp_path / "algs"),
            "results_dir": str(tmp_path / "results"),
            "report": {"per_case": False},
            "metrics": {"tum": {"enabled": True, "fixed_delta": True}},
        }
    )
    key = "orb/fr1_xyz/run1"
    batch = [
        {
            "key": key,
            "truth": str(tmp_path / "truth/fr1_xyz.txt"),
            "estimate": str(tmp_path / "algs/orb/fr1_xyz/run1.txt"),
        }
    ]
    run_stages(batch, tmp_path / "results", cfg, chain.NAMES[:-1])
    assert tables.make([key], tmp_path / "results", cfg) == []
    metrics = json.loads((tmp_path / "results/cases" / key / "06_metrics/metrics.json").read_text())
    _agree(metrics["tum"], "ate_rgbdslam_verbose.txt", "rpe_rgbdslam_fixed_verbose.txt")
    assert (tmp_path / "results/tables/tum.tex").is_file()
    assert "TUM RGB-D" in (tmp_path / "results/error_comparison.txt").read_text()
    header, row = (tmp_path / "results/summary.csv").read_text().splitlines()[:2]
    column = header.split(",").index("tum_ate_rmse_m")
    assert abs(float(row.split(",")[column]) - 0.013473) <= 5e-7


def test_tum_is_a_protocol_of_the_registry_and_off_by_default():
    from epa.outputs.tables import summary
    from epa.workflow import settings

    assert "tum" in registry.protocols()
    cfg = settings.resolve({"truth_dir": ".", "algorithms_dir": "."})
    assert cfg["metrics"]["tum"]["enabled"] is False
    assert "tum_ate_rmse_m" not in summary.columns([8.0], 1.0, metrics=())
    assert "tum_ate_rmse_m" in summary.columns([8.0], 1.0, metrics=(tum.METRIC,))


def _associate_by_the_script(first, second, offset, max_difference):
    """associate.py's loop over every pair, as the script writes it (for small inputs)."""
    cands = sorted(
        (abs(a - (b + offset)), a, b)
        for a in first
        for b in second
        if abs(a - (b + offset)) < max_difference
    )
    fa, fb, out = set(first), set(second), []
    for _, a, b in cands:
        if a in fa and b in fb:
            fa.remove(a)
            fb.remove(b)
            out.append((a, b))
    return sorted(out)


def test_association_is_the_greedy_over_all_pairs():
    rng = np.random.default_rng(3)
    for _ in range(20):
        first = np.unique(np.round(np.cumsum(rng.uniform(0.001, 0.03, 80)), 3))
        second = np.unique(np.round(np.cumsum(rng.uniform(0.001, 0.03, 90)), 3))
        i, j = tum.associate(first, second, 0.004, 0.02)
        got = list(zip(first[i].tolist(), second[j].tolist()))
        assert got == _associate_by_the_script(first.tolist(), second.tolist(), 0.004, 0.02)


def test_association_bound_is_strict_and_each_stamp_is_used_once():
    i, j = tum.associate(np.array([0.0, 1.0]), np.array([0.5, 1.0]), 0.0, 0.5)
    assert (i.tolist(), j.tolist()) == ([1], [1])  # 0.0 - 0.5 is not < 0.5; 1.0 takes 1.0 (diff 0)
    i, j = tum.associate(np.array([0.0, 0.01]), np.array([0.005]), 0.0, 0.02)
    assert (i.tolist(), j.tolist()) == ([0], [0])  # a tie in diff goes to the smaller first stamp


def _find_closest_index(values, t):
    """evaluate_rpe.find_closest_index, as the script writes it."""
    beginning, difference, best, end = 0, abs(values[0] - t), 0, len(values)
    while beginning < end:
        middle = int((end + beginning) / 2)
        if abs(values[middle] - t) < difference:
            difference, best = abs(values[middle] - t), middle
        if t == values[middle]:
            return middle
        elif values[middle] > t:
            end = middle
        else:
            beginning = middle + 1
    return best


def test_closest_index_keeps_the_scripts_tie_rule():
    values = np.arange(50, dtype=float)
    targets = np.concatenate([values + 0.5, values + 2.5, [-3.0, 60.0, 7.0], values * 1.37])
    want = [_find_closest_index(values.tolist(), t) for t in targets.tolist()]
    assert tum.closest_index(values, targets).tolist() == want


def test_random_pairs_are_pythons_draws():
    rng = random.Random(0)
    py3 = [(rng.randint(0, 788), rng.randint(0, 788)) for _ in range(50)]
    assert tum.pose_pairs(
        np.arange(789.0), fixed_delta=False, delta=1, max_pairs=50, sampler="python3"
    ).tolist() == [list(p) for p in py3]
    # Python 2.7's randint(0, n-1): int(random() * n); seed 0 gives the same stream in both Pythons
    first = tum.pose_pairs(
        np.arange(789.0), fixed_delta=False, delta=1, max_pairs=1, sampler="python2"
    )
    assert first.tolist() == [[int(0.8444218515250481 * 789), int(0.7579544029403025 * 789)]]
    rng = random.Random(0)
    index = np.arange(300.0)
    sampled = tum.pose_pairs(index, fixed_delta=True, delta=1, max_pairs=20, sampler="python3")
    pairs = [(i, i + 1) for i in range(298)]
    assert sampled.tolist() == [list(p) for p in rng.sample(pairs, 20)]


def test_small_estimates_take_every_pair_including_each_pose_with_itself():
    pairs = tum.pose_pairs(
        np.arange(5.0), fixed_delta=False, delta=1, max_pairs=10000, sampler="python2"
    )
    assert len(pairs) == 25 and pairs[:6].tolist() == [
        [0, 0],
        [0, 1],
        [0, 2],
        [0, 3],
        [0, 4],
        [1, 0],
    ]


def test_the_relative_error_is_the_scripts_product_bit_for_bit():
    """The stacked products equal evaluate_rpe's per-pair numpy.linalg.inv and numpy.dot calls."""
    rng = np.random.default_rng(1)
    q = rng.normal(size=(40, 4))
    p = rng.normal(size=(40, 3))
    m = tum.transform44(q, p)
    for k in range(40):
        qk = q[k].copy()
        nq = np.dot(qk, qk)
        qk *= np.sqrt(2.0 / nq)
        o = np.outer(qk, qk)
        assert m[k, 0, 0] == 1.0 - o[1, 1] - o[2, 2] and m[k, 1, 2] == o[1, 2] - o[0, 3]
    t = np.arange(40.0)
    rows = tum.rpe(t, m, t, m[::-1].copy(), fixed_delta=True, delta=3, scale=1.3)
    for s0, s1, _, _, trans, rot in rows[:10]:
        e0, e1 = m[::-1][int(s0)], m[::-1][int(s1)]
        g0, g1 = m[int(s0)], m[int(s1)]
        rel = np.dot(np.linalg.inv(e1), e0)
        rel[:3, 3] *= 1.3
        err = np.dot(np.linalg.inv(rel), np.dot(np.linalg.inv(g1), g0))
        assert trans == np.linalg.norm(err[0:3, 3])
        assert rot == np.arccos(min(1, max(-1, (np.trace(err[0:3, 0:3]) - 1) / 2)))


def test_a_repeated_stamp_keeps_its_last_line(tmp_path):
    f = tmp_path / "t.txt"
    f.write_text(
        "# c\n1.0 0 0 0 0 0 0 1\n2.0 1 0 0 0 0 0 1\n1.00 5,6,7 0 0 0 1\n0.5\t9 9 9 0 0 0 1\n"
    )
    t, p = tum_script.positions(f)
    assert t.tolist() == [0.5, 1.0, 2.0] and p[1].tolist() == [5, 6, 7]
    t, p, q = tum_script.poses(f)
    assert t.tolist() == [0.5, 1.0, 2.0] and p[1].tolist() == [5, 6, 7]


def test_rpe_reading_skips_zero_quaternions_and_nan_lines(tmp_path, capsys):
    f = tmp_path / "t.txt"
    f.write_text("1 0 0 0 0 0 0 0\n2 0 0 0 0 0 0 1\n3 nan 0 0 0 0 0 1\n4 0 0 0 0 0 0 1\n")
    t, _, _ = tum_script.poses(f)
    assert t.tolist() == [2.0, 4.0]
    assert f"Warning: line 2 of file '{f}' has NaNs, skipping line" in capsys.readouterr().err


@pytest.mark.parametrize(
    ("text", "says"),
    [
        ("1 0 0\n2 0 0 0\n", ":1: 3 values, a stamp and x y z needs 4"),
        ("1 0 0 0\n2 0 x 0\n", ":2: 'x' is not a number"),
        ("1 0 0 0\n2 0 nan 0\n", ":2: a NaN or infinite value"),
    ],
)
def test_bad_ate_files_are_one_line_errors(tmp_path, text, says):
    f = tmp_path / "bad.txt"
    f.write_text(text)
    with pytest.raises(EpaError, match=says):
        tum_script.positions(f)


def test_the_commands_refuse_in_one_line_with_status_2(tmp_path, capsys):
    a, b = tmp_path / "a.txt", tmp_path / "b.txt"
    a.write_text("1 0 0 0 0 0 0 1\n2 1 0 0 0 0 0 1\n")
    b.write_text("5 0 0 0 0 0 0 1\n6 1 0 0 0 0 0 1\n")
    assert cli.main(["tum-ate", str(a), str(b)]) == 2
    assert "Couldn't find matching timestamp pairs" in capsys.readouterr().err
    assert cli.main(["tum-rpe", str(a), str(a), "--plot", str(tmp_path / "x.png")]) == 2
    assert "only be used in combination with '--fixed_delta'" in capsys.readouterr().err
    assert cli.main(["tum-ate", str(a), str(tmp_path / "missing.txt")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "missing.txt: cannot read the file" in err
    assert not (tmp_path / "x.png").exists()


@needs_data
def test_the_plots_are_written(tmp_path, capsys):
    pytest.importorskip("matplotlib")
    args = [str(FILES["gt"]), str(FILES["orb"])]
    assert cli.main(["tum-ate", *args, "--plot", str(tmp_path / "ate.png")]) == 0
    assert cli.main(["tum-rpe", *args, "--fixed_delta", "--plot", str(tmp_path / "rpe.png")]) == 0
    for name in ("ate.png", "rpe.png"):
        assert (tmp_path / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
