"""Path patterns read as their datasets allow (docs/inputs.md, "Wildcards that share a folder
name"): an estimate's {dataset} takes only the datasets that have a reference, any wildcard takes a
constraint (inline `{run,[0-9]+}` or `inputs.constraints`), and a path read two ways is an error
naming both readings. rpg_trajectory_evaluation's results layout, `laptop_<alg>_<dataset>/
stamped_traj_estimate<n>.txt` with `stamped_groundtruth.txt` beside it, is read by one pattern."""

import re
from pathlib import Path

import pytest
from test_inputs import EXAMPLE, run_grid, write_sheet

from epa.core.errors import EpaError
from epa.workflow import discovery, settings

RPG = "uzh-rpg_rpg_trajectory_evaluation/results"
EUROC = "rpng_open_vins/ov_data/euroc_mav"
EUROC_NAMES = {  # rpg's dataset names -> the references'
    "MH_01": "MH_01_easy",
    "MH_03": "MH_03_medium",
    "MH_04": "MH_04_difficult",
    "MH_05": "MH_05_difficult",
}


def cases_of(inputs: dict, **more) -> list[tuple[str, Path, Path]]:
    cfg = settings.resolve({"inputs": inputs, **more}, source="my.yaml")
    _, cases = discovery.discover_config(cfg, source="my.yaml", say=lambda line: None)
    return [(c.key, Path(c.truth), Path(c.estimate)) for c in cases]


def error_of(inputs: dict) -> str:
    with pytest.raises(EpaError) as err:
        cases_of(inputs)
    return err.value.one_line()


def rpg_tree(root: Path) -> dict[str, Path]:
    """rpg's results layout (flat: no folder per algorithm), its files the example's: MH_01 holds
    the drone_figure8 runs, MH_03 the handheld_office ones; each folder has rpg's ground truth
    copy and eval_cfg.yaml. Returns {case key: estimate}."""
    contents = {"MH_01": "drone_figure8", "MH_03": "handheld_office"}
    runs = {"vislam_ba": ("vio_body", ("0", "1")), "vio_mono": ("vo_drifty", ("0",))}
    made = {}
    for ds, example in contents.items():
        for alg, (source, numbers) in runs.items():
            folder = root / f"laptop_{alg}_{ds}"
            folder.mkdir(parents=True)
            (folder / "stamped_groundtruth.txt").symlink_to(EXAMPLE / f"truth/{example}.txt")
            (folder / "eval_cfg.yaml").write_text("align_type: posyaw\nalign_num_frames: -1\n")
            for n in numbers:
                estimate = folder / f"stamped_traj_estimate{n}.txt"
                estimate.symlink_to(EXAMPLE / f"algorithms/{source}/{example}/run{int(n) + 1}.txt")
                made[f"{alg}/{ds}/{n}"] = estimate
    return made


def test_rpgs_layout_reads_algorithm_and_dataset_and_the_three_ways_agree(tmp_path, caplog):
    """`laptop_{algorithm}_{dataset}` reads `laptop_vislam_ba_MH_01` as vislam_ba and MH_01 (the
    greedy reading, vislam_ba_MH and 01, names no reference); a layout of symlinks and a sheet of
    the same files give the same case names, results and tables."""
    made = rpg_tree(tmp_path / "results")
    # a dataset without a reference stays skipped, said why
    (tmp_path / "results/laptop_vio_mono_V1_01").mkdir()
    (tmp_path / "results/laptop_vio_mono_V1_01/stamped_traj_estimate0.txt").write_text("")
    patterns = {
        "reference": f"{tmp_path}/results/laptop_vio_mono_{{dataset}}/stamped_groundtruth.txt",
        "estimate": f"{tmp_path}/results/laptop_{{algorithm}}_{{dataset}}/stamped_traj_estimate{{run}}.txt",
    }
    found = cases_of(patterns)
    assert [key for key, _, _ in found] == sorted(made)
    assert "skipped 1: inputs.estimate: no reference for dataset '01'" in caplog.text
    assert found[0] == (
        "vio_mono/MH_01/0",
        tmp_path / "results/laptop_vio_mono_MH_01/stamped_groundtruth.txt",
        made["vio_mono/MH_01/0"],
    )
    truth = {key: ref for key, ref, _ in found}
    layout = tmp_path / "layout"
    for key, estimate in made.items():
        alg, ds, run = key.split("/")
        (layout / "algorithms" / alg / ds).mkdir(parents=True, exist_ok=True)
        (layout / "algorithms" / alg / ds / f"{run}.txt").symlink_to(estimate)
        (layout / "truth").mkdir(exist_ok=True)
        if not (layout / "truth" / f"{ds}.txt").exists():
            (layout / "truth" / f"{ds}.txt").symlink_to(truth[key])
    base = {"align": {"method": "posyaw"}, "metrics": {"segments": [8, 16]}}
    keys, by_layout = run_grid(
        {"truth_dir": str(layout / "truth"), "algorithms_dir": str(layout / "algorithms"), **base},
        tmp_path / "by_layout",
    )
    assert keys == sorted(made)
    keys_too, want = run_grid({"inputs": patterns, **base}, tmp_path / "by_patterns")
    assert keys_too == keys
    # the same text, but for the reference's file name ov_eval's comparison prints
    renamed = {
        name: re.sub(r"MH_0[13]\.txt", "stamped_groundtruth.txt", text)
        for name, text in by_layout.items()
    }
    assert want == renamed
    assert "7500 poses in stamped_groundtruth.txt" in want["error_comparison.txt"]
    rows = [(*key.split("/"), est, truth[key]) for key, est in made.items()]
    sheet = {"inputs": {"sheet": str(write_sheet(tmp_path / "runs.tsv", rows))}, **base}
    assert run_grid(sheet, tmp_path / "by_sheet") == (keys, want)


def test_rpgs_own_results_where_they_lie(data, tmp_path, caplog):
    """rpg's example results (../shared/data) against OpenVINS's EuRoC references, rpg's dataset
    names mapped: every vislam folder is read as its algorithm and dataset, and a sheet of the
    same files and a layout of symlinks to them give the same cases."""
    root = data / RPG / "euroc_vislam_mono/laptop"
    inputs = {
        "reference": f"{data / EUROC}/{{dataset}}.txt",
        "estimate": [
            f"{root}/vislam_ba/laptop_{{algorithm}}_{{dataset}}/stamped_ba_estimate{{run}}.txt",
            f"{root}/vislam_rp/laptop_{{algorithm}}_{{dataset}}/stamped_traj_estimate{{run}}.txt",
            f"{data / RPG}/euroc_mono_stereo/laptop/vio_mono/laptop_{{algorithm}}_{{dataset}}/"
            "stamped_traj_estimate.txt",
        ],
        "datasets": EUROC_NAMES,
    }
    found = cases_of(inputs)
    keys = [key for key, _, _ in found]
    assert len(keys) == 4 * 10 + 4 + 3  # ba: 10 runs on MH_01/03/04/05; rp: 1 each; vio_mono: 3
    assert keys[:2] == [
        "vio_mono/MH_01_easy/stamped_traj_estimate",
        "vio_mono/MH_03_medium/stamped_traj_estimate",
    ]
    assert {"vislam_ba/MH_01_easy/0", "vislam_ba/MH_05_difficult/9"} < set(keys)
    assert "vislam_rp/MH_04_difficult/0" in keys
    assert (
        "vislam_ba/MH_04_difficult/7",
        data / EUROC / "MH_04_difficult.txt",
        root / "vislam_ba/laptop_vislam_ba_MH_04/stamped_ba_estimate7.txt",
    ) in found
    assert "skipped" not in caplog.text  # every matched file is a case
    rows = [(*key.split("/"), est, ref) for key, ref, est in found]
    assert cases_of({"sheet": str(write_sheet(tmp_path / "runs.tsv", rows))}) == found
    for key, ref, est in found:
        alg, ds, run = key.split("/")
        (tmp_path / "algorithms" / alg / ds).mkdir(parents=True, exist_ok=True)
        (tmp_path / "algorithms" / alg / ds / f"{run}.txt").symlink_to(est)
        if not (tmp_path / "truth" / f"{ds}.txt").exists():
            (tmp_path / "truth").mkdir(exist_ok=True)
            (tmp_path / "truth" / f"{ds}.txt").symlink_to(ref)
    layout = {"truth_dir": str(tmp_path / "truth"), "algorithms_dir": str(tmp_path / "algorithms")}
    _, by_layout = discovery.discover_config(settings.resolve(layout))
    assert [c.key for c in by_layout] == keys


def test_a_path_read_two_ways_is_an_error_naming_both(tmp_path):
    for name in ("C", "b_C"):
        (tmp_path / f"{name}.txt").write_text("")
    (tmp_path / "laptop_a_b_C").mkdir()
    (tmp_path / "laptop_a_b_C/est.txt").write_text("")
    inputs = {
        "reference": f"{tmp_path}/{{dataset}}.txt",
        "estimate": f"{tmp_path}/laptop_{{algorithm}}_{{dataset}}/est.txt",
    }
    assert error_of(inputs) == (
        f"{tmp_path}/laptop_a_b_C/est.txt: inputs.estimate reads it two ways, algorithm 'a_b',"
        " dataset 'C' and algorithm 'a', dataset 'b_C': constrain {algorithm} or {dataset}"
        " ({algorithm,<regex>} or inputs.constraints.algorithm)"
    )
    # a constraint settles it, inline or in the config, for the pattern and for a sheet alike
    est = tmp_path / "laptop_a_b_C/est.txt"
    inline = {**inputs, "estimate": f"{tmp_path}/laptop_{{algorithm,[a-z]+}}_{{dataset}}/est.txt"}
    assert cases_of(inline) == [("a/b_C/est", tmp_path / "b_C.txt", est)]
    assert cases_of({**inputs, "constraints": {"algorithm": "a_b"}}) == [
        ("a_b/C/est", tmp_path / "C.txt", est)
    ]
    # the inline constraint wins over the config's
    both = {**inline, "constraints": {"algorithm": "a_b"}}
    assert cases_of(both) == [("a/b_C/est", tmp_path / "b_C.txt", est)]


def test_run_constraints_inline_and_in_the_config(tmp_path):
    """`{run,[0-9]+}` (a counted repeat inside a constraint too) leaves out the files whose run is
    no number, as Snakemake's constraint does; `inputs.constraints` does the same for every
    pattern."""
    (tmp_path / "seq.txt").write_text("")
    for name in ("traj0", "traj12", "traj_old", "traj123"):
        (tmp_path / "a" / "seq").mkdir(parents=True, exist_ok=True)
        (tmp_path / "a/seq" / f"{name}.txt").write_text("")
    ref = f"{tmp_path}/{{dataset}}.txt"
    est = f"{tmp_path}/{{algorithm}}/{{dataset}}/traj{{run,[0-9]{{1,2}}}}.txt"
    assert [k for k, _, _ in cases_of({"reference": ref, "estimate": est})] == [
        "a/seq/0",
        "a/seq/12",
    ]
    plain = f"{tmp_path}/{{algorithm}}/{{dataset}}/traj{{run}}.txt"
    assert [k for k, _, _ in cases_of({"reference": ref, "estimate": plain})] == [
        "a/seq/0",
        "a/seq/12",
        "a/seq/123",
        "a/seq/_old",
    ]
    numbered = {"reference": ref, "estimate": plain, "constraints": {"run": "[0-9]+"}}
    assert [k for k, _, _ in cases_of(numbered)] == ["a/seq/0", "a/seq/12", "a/seq/123"]
    # a dataset constraint reaches the reference pattern too: no reference, no case
    assert "inputs.reference" in error_of({**numbered, "constraints": {"dataset": "other"}})


@pytest.mark.parametrize(
    ("inputs", "says"),
    [
        (
            {"estimate": "{T}/{algorithm}/{dataset}/traj{run,[0-9}.txt"},
            "my.yaml: inputs.estimate: {run,[0-9}: '[0-9' is no regular expression (unterminated"
            " character set at position 0)",
        ),
        (
            {"constraints": {"run": "[0-9"}},
            "my.yaml: inputs.constraints.run: '[0-9' is no regular expression (unterminated"
            " character set at position 0)",
        ),
        (
            {"constraints": {"runs": "[0-9]+"}},
            "my.yaml: inputs.constraints: Additional properties are not allowed ('runs' was"
            " unexpected)",
        ),
        (
            {"constraints": {"run": ""}},
            "my.yaml: inputs.constraints.run: '' should be non-empty",
        ),
        (
            {"estimate": "{T}/{algorithm}/{dataset}/traj{run}.txt", "constraints": {"run": 3}},
            "my.yaml: inputs.constraints.run: 3 is not of type 'string'",
        ),
        (
            {"estimate": "{T}/{algorithm}/{dataset}/traj{run,}.txt"},
            "my.yaml: inputs.estimate: an empty constraint for {run} in '{T}/{algorithm}/{dataset}"
            "/traj{run,}.txt'",
        ),
        (
            {"estimate": "{T}/{algorithm}/{dataset}/{algorithm,x}_{algorithm,y}.txt"},
            "my.yaml: inputs.estimate: two different constraints for {algorithm} in",
        ),
        (
            {"estimate": "{T}/{algorithm}/{dataset}.txt", "constraints": {"run": "[0-9]+"}},
            "my.yaml: inputs.constraints.run: no pattern has {run}",
        ),
    ],
)
def test_a_bad_constraint_is_one_line_naming_its_key(tmp_path, inputs, says):
    (tmp_path / "a/seq").mkdir(parents=True)
    (tmp_path / "seq.txt").write_text("")
    (tmp_path / "a/seq/traj0.txt").write_text("")
    given = {
        "reference": f"{tmp_path}/{{dataset}}.txt",
        "estimate": "{T}/{algorithm}/{dataset}/traj{run}.txt",
        **inputs,
    }
    given["estimate"] = given["estimate"].replace("{T}", str(tmp_path))
    said = error_of(given).replace(str(tmp_path), "{T}")
    assert said.startswith(says)


def test_constraints_without_patterns_are_an_error():
    cfg = settings.resolve(
        {
            "truth_dir": str(EXAMPLE / "truth"),
            "algorithms_dir": str(EXAMPLE / "algorithms"),
            "inputs": {"constraints": {"run": "[0-9]+"}},
        }
    )
    with pytest.raises(EpaError, match="inputs.constraints constrain the wildcards of"):
        discovery.discover_config(cfg, source="my.yaml")


def brute_readings(pat, path: str, accept) -> list[dict[str, str]]:
    """Every reading of ``path`` by trying every length of every wildcard's first occurrence."""
    import itertools

    literals, names = pat._parts
    first = list(dict.fromkeys(names))
    found = []
    for lengths in itertools.product(range(1, len(path) + 1), repeat=len(first)):
        values, pos, ok = {}, 0, path.startswith(literals[0])
        pos = len(literals[0])
        for name, literal in zip(names, literals[1:], strict=True):
            size = len(values[name]) if name in values else lengths[first.index(name)]
            value = values.get(name) or path[pos : pos + size]
            ok = ok and path.startswith(value, pos) and "/" not in value and len(value) == size
            values[name] = value
            pos += len(value)
            ok = ok and path.startswith(literal, pos)
            pos += len(literal)
        if ok and pos == len(path) and all(accept(k, v) for k, v in values.items()):
            found.append(values)
    return sorted(found, key=lambda v: [len(v[n]) for n in first], reverse=True)


def test_readings_are_every_reading_the_greedy_one_first():
    """The readings of random paths (letters, '_' and '/') by random patterns are exactly those a
    brute force over every wildcard's length finds, the longest first value first (the reading a
    greedy regular expression gives); where the greedy and lazy expressions agree there is one."""
    import random

    from epa.workflow.patterns import Pattern

    rng = random.Random(7)
    wild = ("{algorithm}", "{dataset}", "{run}")
    seen_ambiguous = seen_unique = 0
    for _ in range(200):
        text = "".join(
            rng.choice(wild) if rng.random() < 0.45 else rng.choice(("_", "a", "/", "x_"))
            for _ in range(rng.randint(2, 5))
        )
        if "{" not in text:
            continue
        pat = Pattern("k", text)
        # mostly a path the pattern makes (each wildcard a random value), sometimes any text
        values = {w: "".join(rng.choice("ab_") for _ in range(rng.randint(1, 3))) for w in wild}
        path = text
        for w in wild:
            path = path.replace(w, values[w])
        if rng.random() < 0.2:
            path = "".join(rng.choice("a_b/") for _ in range(rng.randint(2, 9)))
        known = {"b", "a_b", "b_a"}

        def accept(name, value, known=known):
            return name != "dataset" or value in known

        want = brute_readings(pat, path, accept)
        assert list(pat.readings(path, accept)) == want, (text, path)
        every = brute_readings(pat, path, lambda n, v: True)
        greedy, lazy = pat._shapes
        g, lz = greedy.match(path), lazy.match(path)
        assert (g is not None) == bool(every), (text, path)
        if g is not None and lz is not None:
            assert g.groupdict() == every[0]
            assert (g.groupdict() == lz.groupdict()) == (len(every) == 1), (text, path)
            seen_unique += len(every) == 1
            seen_ambiguous += len(every) > 1
    assert seen_unique > 20 and seen_ambiguous > 20  # both kinds were tried
