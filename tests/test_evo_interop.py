"""evo's result zips both ways, and evo's figures: ``epa ape|rpe --save_results X.zip`` writes what
evo_ape / evo_rpe 1.38.1 write (evo_res prints the same for both), ``epa res`` prints what evo_res
prints for evo's zips, and ``--save_plot`` draws evo's two figures from the zip's own data.

evo runs here as its command-line tools (test oracle only), in a home folder of its own, so that its
settings are its defaults whatever the machine's ~/.evo holds (but for save_traj_in_zip)."""

import argparse
import json
import os
import shutil
import subprocess
import zipfile

import numpy as np
import pytest

pytest.importorskip("evo")
from evo.tools import file_interface  # noqa: E402

from epa.cli import main as cli  # noqa: E402
from epa.evo import archive, commands, plots  # noqa: E402

if not all(shutil.which(tool) for tool in ("evo_ape", "evo_rpe", "evo_res", "evo_config")):
    pytest.skip("evo's command-line tools are not on PATH", allow_module_level=True)

# |epa - evo| per array element and pose matrix entry, in the array's unit (m, deg, s, unit-less).
# Measured worst over the cases below: 2.3e-13 (KITTI 00 ORB, the RPE's errors and aligned poses,
# coordinates up to 560 m); stamps and the reference's distances are the same bytes.
ATOL = 1e-10

D = "MichaelGrupp_evo/test/data"
# name: (command, form, files (under D), evo's options, epa's extra options)
CASES = {
    "ape_se3": (
        "ape",
        "tum",
        ("freiburg1_xyz-groundtruth.txt", "freiburg1_xyz-rgbdslam.txt"),
        ["-a"],
        [],
    ),
    "ape_scale_only": (
        "ape",
        "tum",
        ("freiburg1_xyz-groundtruth.txt", "freiburg1_xyz-ORB_kf_mono.txt"),
        ["-s"],
        [],
    ),
    "ape_origin_xy": (
        "ape",
        "tum",
        ("freiburg1_xyz-groundtruth.txt", "freiburg1_xyz-ORB_kf_mono.txt"),
        ["--align_origin", "--project_to_plane", "xy", "-r", "full"],
        [],
    ),
    "rpe_ratio_euroc": (
        "rpe",
        "euroc",
        ("V102_groundtruth.csv", "V102.txt"),
        ["-a", "-r", "point_distance_error_ratio", "-d", "1", "-u", "m", "--t_offset", "0.003"],
        ["--unsorted", "keep"],  # V102.txt repeats 4 stamps, which evo keeps
    ),
    "rpe_interp_sim3": (
        "rpe",
        "tum",
        ("freiburg1_xyz-groundtruth.txt", "freiburg1_xyz-ORB_kf_mono.txt"),
        ["-as", "-r", "angle_deg", "--sync_method", "interpolation", "--all_pairs", "-d", "2"],
        [],
    ),
    "rpe_kitti": ("rpe", "kitti", ("KITTI_00_gt.txt", "KITTI_00_ORB.txt"), ["-as", "-d", "10"], []),
    "ape_mcap": ("ape", "mcap", ("nav2_turtlebot.mcap", "/amcl_pose", "/odom"), ["-a"], []),
}


@pytest.fixture(scope="session")
def evo_home(tmp_path_factory):
    home = tmp_path_factory.mktemp("evo_home")
    run_evo(home, "evo_config", "show", "--brief")  # evo writes its default settings on first run
    # evo keeps the trajectories out of its zips unless told; epica always writes them
    run_evo(home, "evo_config", "set", "save_traj_in_zip", "true")
    return home


def run_evo(home, tool, *args) -> str:
    done = subprocess.run(
        [tool, *map(str, args)],
        env={**os.environ, "HOME": str(home)},
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert done.returncode == 0, (tool, args, done.stdout, done.stderr)
    return done.stdout


def case_paths(data, name):
    kind, form, files, evo_opts, epa_opts = CASES[name]
    d = data / D
    inputs = [str(d / files[0]), *files[1:]] if form == "mcap" else [str(d / f) for f in files]
    return kind, form, inputs, evo_opts, epa_opts


def both_zips(data, evo_home, tmp_path, name):
    """evo's and epica's zips of the same pair with the same options."""
    kind, form, inputs, evo_opts, epa_opts = case_paths(data, name)
    theirs, ours = tmp_path / f"{name}_evo.zip", tmp_path / f"{name}_epa.zip"
    run_evo(
        evo_home, f"evo_{kind}", form, *inputs, *evo_opts, "--save_results", theirs, "--no_warnings"
    )
    argv = [kind, form, *inputs, *evo_opts, *epa_opts, "--save_results", str(ours), "--silent"]
    assert cli.main(argv) == 0
    return theirs, ours


@pytest.mark.parametrize("name", list(CASES))
def test_evo_res_prints_the_same_for_our_zip(data, evo_home, tmp_path, name, capsys):
    theirs, ours = both_zips(data, evo_home, tmp_path, name)
    capsys.readouterr()
    printed = run_evo(evo_home, "evo_res", ours)
    assert printed == run_evo(evo_home, "evo_res", theirs)
    assert "rmse" in printed and CASES[name][0].upper() in printed
    # and what evo reads from the zips beyond the printout: the same info, arrays and trajectories
    a = file_interface.load_res_file(theirs, load_trajectories=True)
    b = file_interface.load_res_file(ours, load_trajectories=True)
    assert b.info == a.info
    assert list(b.stats) == list(a.stats)
    for key in a.stats:
        assert abs(b.stats[key] - a.stats[key]) <= ATOL * max(1.0, a.stats["sse"]), key
    assert list(b.np_arrays) == list(a.np_arrays)
    for key, array in a.np_arrays.items():
        assert b.np_arrays[key].shape == array.shape, key
        np.testing.assert_allclose(b.np_arrays[key], array, rtol=0, atol=ATOL, err_msg=key)
    assert list(b.trajectories) == list(a.trajectories)
    for key, traj in a.trajectories.items():
        other = b.trajectories[key]
        assert type(other) is type(traj) and other.num_poses == traj.num_poses
        np.testing.assert_allclose(
            np.array(other.poses_se3), np.array(traj.poses_se3), rtol=0, atol=ATOL
        )
        if hasattr(traj, "timestamps"):
            np.testing.assert_array_equal(other.timestamps, traj.timestamps)
    # evo's layout: its entry order, with the trajectories (evo's save_traj_in_zip) last
    names = zipfile.ZipFile(ours).namelist()
    assert names[:2] == ["info.json", "stats.json"]
    assert names[2:-2] == [f"{k}.npy" for k in a.np_arrays]
    suffix = ".kitti" if CASES[name][1] == "kitti" else ".tum"
    assert all(n.endswith(suffix) for n in names[-2:])


def test_our_zip_is_the_same_bytes_each_time(data, tmp_path):
    kind, form, inputs, evo_opts, _ = case_paths(data, "ape_se3")
    out = []
    for k in range(2):
        assert (
            cli.main([kind, form, *inputs, "-a", "--save_results", str(tmp_path / f"{k}.zip")]) == 0
        )
        out.append((tmp_path / f"{k}.zip").read_bytes())
    assert out[0] == out[1]


def test_epa_res_prints_what_evo_res_prints(data, evo_home, tmp_path, capsys):
    zips = []
    for name in ("ape_se3", "rpe_kitti", "ape_mcap"):
        kind, form, inputs, evo_opts, _ = case_paths(data, name)
        zips.append(tmp_path / f"{name}.zip")
        run_evo(evo_home, f"evo_{kind}", form, *inputs, *evo_opts, "--save_results", zips[-1])
    for group, flags in (
        (zips[:1], []),
        (zips[1:2], ["--use_filenames"]),
        (zips, []),  # three titles: evo_res asks whether to go on, --no_warnings does
    ):
        want = run_evo(evo_home, "evo_res", *group, *flags, "--no_warnings")
        capsys.readouterr()
        assert cli.main(["res", *map(str, group), *flags]) == 0
        got = capsys.readouterr()
        assert got.out == want
        warned = got.err.strip().splitlines()
        assert (
            len(warned) == len({archive.read(zipfile.ZipFile(z), str(z)).title for z in group}) - 1
        )
    # the statistics behind the printout, at full precision, in --save_table
    assert cli.main(["res", str(zips[0]), "--save_table", str(tmp_path / "t.csv")]) == 0
    stats = json.loads(zipfile.ZipFile(zips[0]).read("stats.json"))
    row = (tmp_path / "t.csv").read_text().splitlines()[1].split(",")
    assert row[1] == "APE w.r.t. translation part (m)"
    assert row[2:] == [
        f"{stats[k]:.6f}" for k in ("rmse", "mean", "median", "std", "min", "max", "sse")
    ]


def test_epa_res_reads_evo_zips_beside_epica_files(data, evo_home, tmp_path, capsys):
    kind, form, inputs, evo_opts, _ = case_paths(data, "ape_se3")
    theirs = tmp_path / "evo.zip"
    run_evo(evo_home, "evo_ape", form, *inputs, *evo_opts, "--save_results", theirs)
    mine = tmp_path / "epa.json"
    assert cli.main(["rpe", form, *inputs, "-a", "--save_results", str(mine), "--silent"]) == 0
    # the zip layout epica wrote before: result.json (epica-result/1) and errors.csv
    old = tmp_path / "old.zip"
    doc = json.loads(mine.read_text())
    with zipfile.ZipFile(old, "w") as z:
        z.writestr("result.json", json.dumps({k: v for k, v in doc.items() if k != "errors"}))
        z.writestr("errors.csv", "error\n" + "".join(f"{e!r}\n" for e in doc["errors"]))
    capsys.readouterr()
    assert cli.main(["res", str(theirs), str(mine), str(old)]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0].split() == [
        "result",
        "metric",
        "rmse",
        "mean",
        "median",
        "std",
        "min",
        "max",
        "sse",
    ]
    evo_stats = json.loads(zipfile.ZipFile(theirs).read("stats.json"))
    assert lines[1].startswith(str(theirs)) and "APE w.r.t. translation part (m)" in lines[1]
    assert f"{evo_stats['rmse']:.6f}  {evo_stats['mean']:.6f}" in lines[1]
    for line in lines[2:]:
        assert "RPE w.r.t. translation part (m)" in line and f"{doc['stats']['rmse']:.6f}" in line


@pytest.mark.parametrize(
    "entries, why",
    [
        ({"info.json": "{}", "stats.json": '{"rmse": 1.0}'}, "holds no title"),
        ({"info.json": '{"title": "APE"}', "stats.json": '{"rmse": NaN}'}, "not a finite number"),
        ({"info.json": '{"title": "APE"}', "stats.json": "{"}, "unreadable JSON"),
    ],
)
def test_a_broken_evo_zip_is_one_line(tmp_path, capsys, entries, why):
    bad = tmp_path / "bad.zip"
    with zipfile.ZipFile(bad, "w") as z:
        for name, text in entries.items():
            z.writestr(name, text)
    assert cli.main(["res", str(bad)]) == 2
    err = capsys.readouterr().err.strip()
    assert "bad.zip" in err and why in err and "\n" not in err


def test_repeated_labels_are_refused_as_evo_res_refuses(data, tmp_path, capsys):
    kind, form, inputs, evo_opts, _ = case_paths(data, "ape_se3")
    for k in range(2):
        assert (
            cli.main([kind, form, *inputs, "-a", "--save_results", str(tmp_path / f"{k}.zip")]) == 0
        )
    capsys.readouterr()
    assert cli.main(["res", str(tmp_path / "0.zip"), str(tmp_path / "1.zip")]) == 2
    err = capsys.readouterr().err.strip()
    assert "freiburg1_xyz-rgbdslam.txt" in err and "--use_filenames" in err and "\n" not in err
    assert (
        cli.main(["res", str(tmp_path / "0.zip"), str(tmp_path / "1.zip"), "--use_filenames"]) == 0
    )


# ----------------------------------------------------------------------------- figures
def result_of(data, name):
    """The result `epa ape|rpe` computes for a case, from its command line."""
    kind, form, inputs, evo_opts, epa_opts = case_paths(data, name)
    parser = argparse.ArgumentParser()
    commands.add_parsers(parser.add_subparsers(dest="command"))
    return commands.compute(parser.parse_args([kind, form, *inputs, *evo_opts, *epa_opts]))


@pytest.mark.parametrize(
    "name, mode", [("ape_se3", "xyz"), ("rpe_ratio_euroc", "xy"), ("rpe_kitti", "xz")]
)
def test_the_figures_hold_the_zips_data(data, name, mode):
    import matplotlib.pyplot as plt
    from matplotlib.collections import LineCollection

    result = result_of(data, name)
    arrays = archive.arrays(result)
    figs = plots.draw(result, plot_mode=mode)
    raw = figs["raw"].axes[0]
    curve = raw.lines[0]
    want_x = arrays.get("seconds_from_start", np.arange(len(result.errors)))  # KITTI: by index
    np.testing.assert_array_equal(curve.get_xdata(), want_x)
    np.testing.assert_array_equal(curve.get_ydata(), arrays["error_array"])
    levels = {line.get_label(): line.get_ydata()[0] for line in raw.lines[1:]}
    assert levels == {k: result.stats[k] for k in ("rmse", "median", "mean")}
    patch = raw.patches[0]  # evo's std band: one std wide about the mean (y in data units)
    band = patch.get_patch_transform().transform(patch.get_path().vertices)[:, 1]
    assert np.isclose(band.min(), result.stats["mean"] - result.stats["std"] / 2)
    assert np.isclose(band.max(), result.stats["mean"] + result.stats["std"] / 2)
    assert raw.get_title() == result.title
    ax = figs["map"].axes[0]
    line = next(c for c in ax.collections if isinstance(c, LineCollection))
    ref, est = archive.poses(result)
    # one segment per pose step, coloured by the error of the pose (or pair) it ends at
    assert len(est) - 1 == len(result.errors) - (1 if result.ends is None else 0)
    np.testing.assert_array_equal(line.get_array(), result.errors[: len(est) - 1])
    assert line.norm.vmin == result.stats["min"] and line.norm.vmax == result.stats["max"]
    if mode != "xyz":
        axes = ["xyz".index(c) for c in mode]
        np.testing.assert_allclose(line.get_segments()[0], est.p[:2][:, axes])
        np.testing.assert_allclose(ax.lines[0].get_xydata(), ref.p[:, axes])
    for fig in figs.values():
        plt.close(fig)


def test_save_plot_writes_evos_files(data, tmp_path, capsys, monkeypatch):
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    kind, form, inputs, evo_opts, epa_opts = case_paths(data, "rpe_ratio_euroc")
    argv = [kind, form, *inputs, *evo_opts, *epa_opts, "--silent"]
    assert cli.main([*argv, "--save_plot", str(tmp_path / "p.png"), "--plot_mode", "xy"]) == 0
    assert (
        capsys.readouterr().out.strip()
        == f"wrote {tmp_path / 'p_raw.png'}, {tmp_path / 'p_map.png'}"
    )
    for part in ("raw", "map"):
        head = (tmp_path / f"p_{part}.png").read_bytes()[:24]
        assert head[:8] == b"\x89PNG\r\n\x1a\n"
        width, height = int.from_bytes(head[16:20], "big"), int.from_bytes(head[20:24], "big")
        assert (width, height) == tuple(int(v * 150) for v in plots.SIZE[part])
    # --plot with no display: the file, and a line saying so; a PDF holds both figures as pages
    assert cli.main([*argv, "--plot", "--save_plot", str(tmp_path / "p.pdf")]) == 0
    assert capsys.readouterr().out.strip() == f"no display for --plot: wrote {tmp_path / 'p.pdf'}"
    pdf = (tmp_path / "p.pdf").read_bytes()
    assert pdf.startswith(b"%PDF") and pdf.count(b"/Type /Page\n") + pdf.count(b"/Type /Page ") == 2
    assert sorted(p.name for p in tmp_path.iterdir()) == ["p.pdf", "p_map.png", "p_raw.png"]


@pytest.mark.parametrize(
    "extra, why",
    [
        (["--plot"], "--plot: no display to open a window on"),
        (["--plot_mode", "xy"], "--plot_mode draws nothing without --plot or --save_plot"),
        (["--save_plot", "figure.gif"], "--save_plot needs a file suffix among"),
    ],
)
def test_plot_mistakes_are_one_line_before_any_work(
    data, tmp_path, capsys, monkeypatch, extra, why
):
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    monkeypatch.chdir(tmp_path)
    kind, form, inputs, evo_opts, epa_opts = case_paths(data, "ape_se3")
    assert cli.main([kind, form, *inputs, *evo_opts, *epa_opts, *extra]) == 2
    captured = capsys.readouterr()
    assert captured.out == ""  # refused before computing: no statistics block
    err = captured.err.strip()
    assert why in err and "\n" not in err
    assert list(tmp_path.iterdir()) == []


def test_plot_with_a_display_shows_the_figures_and_writes_nothing(
    data, tmp_path, capsys, monkeypatch
):
    import matplotlib.pyplot as plt

    shown = []
    monkeypatch.setattr(plots, "can_show", lambda: True)
    monkeypatch.setattr(plt, "show", lambda: shown.append(sorted(plt.get_fignums())))
    monkeypatch.chdir(tmp_path)
    kind, form, inputs, evo_opts, epa_opts = case_paths(data, "ape_se3")
    before = plt.get_fignums()
    assert cli.main([kind, form, *inputs, *evo_opts, *epa_opts, "--plot", "--silent"]) == 0
    assert len(shown) == 1 and len(shown[0]) == len(before) + 2  # raw and map, open when shown
    assert plt.get_fignums() == before  # closed after the windows are
    assert capsys.readouterr().out == "" and list(tmp_path.iterdir()) == []


def test_no_display_no_window(monkeypatch):
    monkeypatch.setattr(plots.sys, "platform", "linux")
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    assert plots.can_show() is False
