"""The docs name only what exists: every config key (`metrics.sim3_check.max_ate_ratio`), every
`epa` command and its options (`epa eval --align`), and every output file or folder
(`06_metrics/metrics.json`, `tables/ate_per_axis.tex`) that README.md and docs/*.md name in code
is looked up in the schema, the command line's parsers and the files the bundled example writes.

The checks read code spans and code blocks only: prose is free to talk about evo's or ov_eval's
options, a name in backticks is a promise about epica."""

from __future__ import annotations

import argparse
import os
import re
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from epa.workflow import settings

ROOT = Path(__file__).resolve().parents[1]
SCHEMA = ROOT / "src/epa/workflow/config.schema.yaml"

# Files a doc may name that the bundled example (mode epa, default settings) does not write, each
# with what writes it; every one is checked to be a name some other source of the repository spells.
NOT_IN_THE_EXAMPLE = {
    "rpg_*": "mode rpg and `epa rpg` (rpg_trajectory_evaluation's files)",
    "10_report/*.rrd": "`epa eval --rerun`",
    "verify.json": "`epa verify`",
    "*.verify.json": "`epa verify` of a package",
    "06_metrics/rpg/*": "mode rpg (rpg_trajectory_evaluation's files)",
    "06_metrics/eth3d/*": "metrics.eth3d (the ETH3D program's printed output)",
}
# Paths in code that are not outputs, by the doc that names them.
NOT_OUTPUTS = {
    ("docs/architecture.md", "07_metrics"): "the folder a renumbering would give",
    ("docs/bad-inputs.md", "results/{algorithm}/{dataset}/{run}.txt"): "an input path pattern",
}
EXTENSIONS = ("json", "csv", "txt", "tex", "tum", "png", "pdf", "md", "yaml", "rrd", "tsv", "log")
NOT_SETTINGS = (*EXTENSIONS, "py", "html", "svg", "gz")  # `grid.py`, `report.html`: file names
OUTPUT_TOPS = ("results/", "tables/", "figures/", "paper/", "consistency/", "cases/")


def doc_files(root: Path = ROOT) -> list[Path]:
    return [root / "README.md", *sorted((root / "docs").glob("*.md"))]


# ----------------------------------------------------------------------------- reading the docs
def code_of(text: str) -> list[tuple[int, str]]:
    """(line number, text) of every inline code span and every line of a fenced code block."""
    out = []
    fenced = False
    for n, line in enumerate(text.splitlines(), 1):
        if line.lstrip().startswith("```"):
            fenced = not fenced
            continue
        if fenced:
            out.append((n, line))
            continue
        for m in re.finditer(r"(`+)(.+?)\1", line):
            out.append((n, m.group(2).strip()))
    return out


def yaml_blocks(text: str) -> list[tuple[int, str]]:
    """(first line, text) of every ```yaml block."""
    return [
        (text[: m.start()].count("\n") + 2, m.group(1))
        for m in re.finditer(r"^```ya?ml\n(.*?)^```", text, re.M | re.S)
    ]


# ----------------------------------------------------------------------------- config keys
def _schema() -> dict:
    return yaml.safe_load(SCHEMA.read_text(encoding="utf-8"))


def _resolve(node: dict, schema: dict) -> list[dict]:
    """The node and the branches it may take (a $ref followed, oneOf/anyOf/allOf spread)."""
    if "$ref" in node:
        return _resolve(settings._pointer(schema, node["$ref"]), schema)
    out = [node]
    for key in ("oneOf", "anyOf", "allOf"):
        for branch in node.get(key, []):
            out += _resolve(branch, schema)
    return out


PLACEHOLDER = re.compile(r"^(<[^>]+>|\{[^}]+\}|\*|NAME|[A-Z]+)$")


def key_exists(dotted: str, schema: dict) -> bool:
    """Whether ``a.b.c`` is a setting: each part a property, or a name a mapping takes (any name
    where the schema has additionalProperties or patternProperties; a placeholder such as
    ``<dataset>`` or ``{alg}`` only there)."""
    nodes = [schema]
    for part in dotted.split("."):
        nxt = []
        for node in (b for n in nodes for b in _resolve(n, schema)):
            props = node.get("properties", {})
            if part in props:
                nxt.append(props[part])
                continue
            if PLACEHOLDER.match(part):  # `metrics.<name>.enabled`: any of them
                nxt += props.values()
            if part.isdigit() and isinstance(node.get("items"), dict):  # `metrics.rpe.0.delta`
                nxt.append(node["items"])
            extra = node.get("additionalProperties")
            if isinstance(extra, dict):
                nxt.append(extra)
            for pattern, sub in node.get("patternProperties", {}).items():
                if PLACEHOLDER.match(part) or re.search(pattern, part):
                    nxt.append(sub)
        if not nxt:
            return False
        nodes = nxt
    return True


DOTTED = re.compile(
    r"(?<![\w./<{-])([a-z][a-z0-9_]*(?:\.(?:[a-z0-9_]+|<[^>\s]+>|\{[^}\s]+\}|\*))+)"
)


def python_name(dotted: str) -> bool:
    """Whether ``a.b.c`` is a module of epa or a name in one (`metrics.spec`, `steps.rpg`)."""
    import importlib

    parts = dotted.split(".")
    for i in range(len(parts), 0, -1):
        try:
            obj = importlib.import_module("epa." + ".".join(parts[:i]))
        except ImportError:
            continue
        for attr in parts[i:]:
            if not hasattr(obj, attr):
                return False
            obj = getattr(obj, attr)
        return True
    return False


def config_keys_named(text: str, tops: set[str]) -> list[tuple[int, str]]:
    """Every dotted name in code whose first part is a top-level setting (`calibrate.scale`), but
    file names (`metrics.json`) and Python names (`epa.evaluate`)."""
    out = []
    for n, code in code_of(text):
        for m in DOTTED.finditer(code):
            name = m.group(1)
            parts = name.split(".")
            if parts[0] not in tops or parts[-1] in NOT_SETTINGS:
                continue
            if code[m.end() : m.end() + 1] == "(":  # a call: a Python name
                continue
            out.append((n, name))
    return out


def yaml_keys(doc, prefix=()) -> list[str]:
    if not isinstance(doc, dict):
        return []
    out = []
    for k, v in doc.items():
        out.append(".".join((*prefix, str(k))))
        out += yaml_keys(v, (*prefix, str(k)))
    return out


def config_problems(text: str, schema: dict) -> list[str]:
    tops = set(schema["properties"])
    bad = [
        f"line {n}: `{name}` is no setting"
        for n, name in config_keys_named(text, tops)
        if not key_exists(name, schema) and not python_name(name)
    ]
    for n, block in yaml_blocks(text):  # a config (its keys include a top-level setting)
        try:
            doc = yaml.safe_load(block)
        except yaml.YAMLError:
            continue
        if not isinstance(doc, dict) or not set(doc) & tops:
            continue
        bad += [
            f"line {n}+: `{k}` is no setting" for k in yaml_keys(doc) if not key_exists(k, schema)
        ]
    # `snakemake --config key=value`: Snakemake's top-level keys
    for n, code in code_of(text):
        for m in re.finditer(r"--config((?:\s+[\w.]+=\S+)+)", code):
            for pair in m.group(1).split():
                key = pair.split("=")[0]
                if "snakemake" in code and not key_exists(key, schema):
                    bad.append(f"line {n}: `--config {pair}`: `{key}` is no setting")
    return bad


# ----------------------------------------------------------------------------- commands
def epa_parsers() -> dict[str, argparse.ArgumentParser]:
    """Each `epa` command's parser, built as `epa --help` builds them ("" is `epa` itself)."""
    from epa.cli import main as cli

    top = cli._parser()
    sub = next(a for a in top._actions if isinstance(a, argparse._SubParsersAction))
    return {"": top, **sub.choices}


SEPARATORS = {"|", "||", "&&", ";", ">", ">>", "2>", "#", "\\"}


def commands_named(text: str) -> list[tuple[int, str, list[str]]]:
    """(line, command, its words) of every `epa COMMAND ...` in code."""
    out = []
    for n, code in code_of(text):
        for m in re.finditer(r"(?:^|[\s(`$])epa ((?:-{1,2})?[a-z][\w|-]*)(.*)", code):
            try:
                words = shlex.split(m.group(2), comments=True)
            except ValueError:  # an unbalanced quote in prose-like code
                words = m.group(2).split()
            rest = []
            for w in words:
                if w in SEPARATORS or w.startswith(("#", "|", "&", ";")):
                    break
                rest.append(w)
            out.append((n, m.group(1), rest))
    return out


def options_of(parser: argparse.ArgumentParser, words: list[str]) -> dict[str, argparse.Action]:
    """A command's options; under a command with forms (`epa ape tum`), the named form's, or any
    form's when none is named."""
    options = {s: a for a in parser._actions for s in a.option_strings}
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            named = [w for w in words if w in action.choices][:1]
            for form in named or list(action.choices):
                options.update(options_of(action.choices[form], []))
    return options


def command_problems(text: str, parsers: dict) -> list[str]:
    bad = []
    for n, command, words in commands_named(text):
        if command.startswith("-"):  # `epa --version`
            words, command = [command, *words], ""
        names = [c for c in command.split("|") if c] if command else [""]
        for name in names:
            parser = parsers.get(name)
            if parser is None:
                bad.append(f"line {n}: `epa {name}` is no command")
                continue
            options = options_of(parser, words)
            for i, w in enumerate(words):
                if not re.match(r"^--?[A-Za-z]", w):
                    continue
                opt = w.split("=")[0]
                if re.match(r"^-[A-Za-z]{2,}$", opt) and opt not in options:  # `-as`: -a -s
                    if all(f"-{c}" in options for c in opt[1:]):
                        continue
                if opt not in options:
                    bad.append(f"line {n}: `epa {name} {opt}`: no such option")
                    continue
                choices = options[opt].choices
                value = (
                    w.split("=", 1)[1]
                    if "=" in w
                    else (words[i + 1] if i + 1 < len(words) else None)
                )
                if choices and value and not value.startswith(("<", "{", "-")) and value.isascii():
                    for v in value.split("|"):
                        if v not in map(str, choices) and v.upper() != v:
                            bad.append(
                                f"line {n}: `epa {name} {opt} {v}`: not one of {list(choices)}"
                            )
    return bad


# ----------------------------------------------------------------------------- output files
FILE = re.compile(
    r"(?<![\w./-])((?:[\w{}<>*.-]+/)*[\w{}<>*.,-]+\.(?:"
    + "|".join(EXTENSIONS)
    + r")|\d\d_[a-z_]+/?)(?![\w/])"
)


def outputs_named(text: str) -> list[tuple[int, str]]:
    """(line, name) of every output path in code: a name under a stage folder (`01_load/timing.csv`)
    or under one of the results folder's own folders (`tables/ate.tex`), or a stage folder itself."""
    out = []
    for n, code in code_of(text):
        if re.match(r"^\s*(\$ )?(cp|ln|mkdir|curl|wget|pip|git) ", code):
            continue
        for m in FILE.finditer(code):
            name = m.group(1)
            if re.search(r"(^|/)\d\d_[a-z_]+", name) or name.startswith(OUTPUT_TOPS):
                out.append((n, name))
    return out


def _pattern(name: str) -> re.Pattern:
    """A named path as a pattern over the example's relative paths: placeholders (`{run}`,
    `<alg>`, `*`, `N`) match one part; `{a,b}` either; it matches at the end of a path."""
    name = name.rstrip("/").removeprefix("results/")
    out = ""
    for token in re.split(r"(\{[^}]*\}|<[^>]*>|\*|\.\.\.|…)", name):
        if not token:
            continue
        if token.startswith("{") and "," in token:
            out += "(" + "|".join(re.escape(t) for t in token[1:-1].split(",")) + ")"
        elif token[0] in "{<*" or token in ("...", "…"):
            out += r"[^/]*"
        else:
            out += re.escape(token)
    return re.compile(r"(^|/)" + out + r"(/|$)")


def output_problems(text: str, made: list[str], doc: str = "") -> list[str]:
    bad = []
    for n, name in outputs_named(text):
        if (doc, name) in NOT_OUTPUTS:
            continue
        stage = re.search(r"\d\d_[a-z_]+(/.*)?$", name)  # `case/06_metrics/x`: from the stage on
        name = stage.group(0) if stage else name
        name = re.sub(r"(^|/)\.([^/]+)$", r"\1\2", name)  # `.xcorr.csv`: xcorr.csv's temporary name
        pattern = _pattern(name)
        if any(pattern.search(p) for p in made):
            continue
        if any(_pattern(other).search(name.rstrip("/")) for other in NOT_IN_THE_EXAMPLE):
            continue
        bad.append(f"line {n}: `{name}` is not written by the example")
    return bad


# ----------------------------------------------------------------------------- fixtures
def declared_outputs() -> list[str]:
    """What the metrics that the example leaves off write when switched on, as the registry declares
    it: each one's tables (`tables/<name>.tex`, also in `paper/tables/`) and per-case arrays
    (under its stage's folder)."""
    from epa.artifacts.stage import folder
    from epa.metrics import registry
    from epa.workflow import chain

    out = []
    for stage in chain.NAMES:
        for metric in registry.computed_in(stage):
            out += [f"cases/a/d/r/{folder(stage)}/{name}" for name in metric.arrays]
            for table in metric.tables:
                out += [f"tables/{table.name}.tex", f"paper/tables/{table.name}.tex"]
    return out


@pytest.fixture(scope="session")
def example_outputs(tmp_path_factory) -> list[str]:
    """The bundled example run once as the README says (`snakemake --cores 2`, its results under a
    temporary folder): every path it writes, relative to the results folder, and the declared
    outputs of the metrics it leaves off."""
    top = tmp_path_factory.mktemp("example")
    cfg = yaml.safe_load((ROOT / "config/config.yaml").read_text(encoding="utf-8"))
    cfg.update(
        truth_dir=str(ROOT / cfg["truth_dir"]),
        algorithms_dir=str(ROOT / cfg["algorithms_dir"]),
        results_dir=str(top / "results"),
    )
    (top / "config.yaml").write_text(yaml.safe_dump(cfg))
    cmd = [sys.executable, "-m", "snakemake", "-s", str(ROOT / "Snakefile"), "--cores", "2"]
    cmd += ["--configfile", str(top / "config.yaml"), "--directory", str(top)]
    run = subprocess.run(cmd, cwd=top, capture_output=True, text=True, timeout=1200)
    assert run.returncode == 0, (run.stdout + run.stderr)[-3000:]
    results = top / "results"
    made = sorted(str(p.relative_to(results)) for p in results.rglob("*"))
    return made + declared_outputs()


# ----------------------------------------------------------------------------- the tests
DOCS = [p.relative_to(ROOT).as_posix() for p in doc_files()]


@pytest.mark.parametrize("doc", DOCS)
def test_every_setting_a_doc_names_is_in_the_schema(doc):
    assert config_problems((ROOT / doc).read_text(encoding="utf-8"), _schema()) == []


@pytest.mark.parametrize("doc", DOCS)
def test_every_command_and_option_a_doc_names_exists(doc):
    assert command_problems((ROOT / doc).read_text(encoding="utf-8"), epa_parsers()) == []


@pytest.mark.parametrize("doc", DOCS)
def test_every_output_a_doc_names_is_written(doc, example_outputs):
    assert output_problems((ROOT / doc).read_text(encoding="utf-8"), example_outputs, doc) == []


def test_the_checks_find_a_renamed_setting_option_and_file(tmp_path, example_outputs):
    """The checks above can fail: a setting renamed in a copy of the schema fails the docs that
    name it; a copy of the docs with one setting, one option and one file misspelt fails each
    check, where the copy as it is passes."""
    copy = tmp_path / "repo"
    (copy / "docs").mkdir(parents=True)
    for p in doc_files():
        shutil.copy(p, copy / p.relative_to(ROOT))
    schema, parsers = _schema(), epa_parsers()
    metrics = (copy / "docs/metrics.md").read_text(encoding="utf-8")
    assert "`metrics.segment_tol`" in metrics and config_problems(metrics, schema) == []
    # the schema's key renamed, the docs not
    text = SCHEMA.read_text(encoding="utf-8").replace(
        "      segment_tol:", "      segment_tolerance:"
    )
    (tmp_path / "schema.yaml").write_text(text, encoding="utf-8")
    renamed_schema = yaml.safe_load((tmp_path / "schema.yaml").read_text(encoding="utf-8"))
    assert "segment_tolerance" in renamed_schema["properties"]["metrics"]["properties"]
    said = config_problems(metrics, renamed_schema)
    assert any("`metrics.segment_tol` is no setting" in p for p in said), said
    # the docs' key misspelt
    said = config_problems(
        metrics.replace("`metrics.segment_tol`", "`metrics.segment_tols`"), schema
    )
    assert any("`metrics.segment_tols` is no setting" in p for p in said), said
    readme = (copy / "README.md").read_text(encoding="utf-8")
    assert "epa eval REF EST --out DIR" in readme and command_problems(readme, parsers) == []
    said = command_problems(
        readme.replace("eval REF EST --out DIR", "eval REF EST --output DIR"), parsers
    )
    assert any("`epa eval --output`: no such option" in p for p in said), said
    stages = (copy / "docs/stages.md").read_text(encoding="utf-8")
    assert "`01_load/timing.csv`" in stages and output_problems(stages, example_outputs) == []
    said = output_problems(
        stages.replace("`01_load/timing.csv`", "`01_load/times.csv`"), example_outputs
    )
    assert any("`01_load/times.csv` is not written" in p for p in said), said


# ----------------------------------------------------------------------------- the release
def _readme_module_recipe() -> str:
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    return next(b for b in re.findall(r"```python\n(.*?)```", text, re.S) if "module epica:" in b)


def test_the_readme_names_this_release_and_the_changelog_has_it():
    from epa import __version__

    tag = f"v{__version__}"
    recipe = _readme_module_recipe()
    assert re.findall(r'tag="([^"]+)"', recipe) == [tag]
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    assert set(re.findall(r"--(?:tag|branch) (v[\d.]+)", readme)) == {tag}
    assert set(re.findall(r"@(v\d+\.\d+\.\d+)", readme)) == {tag}
    changelog = (ROOT / "CHANGELOG.md").read_text(encoding="utf-8")
    assert "## [Unreleased]" in changelog
    assert re.search(
        rf"^## \[{re.escape(__version__)}\] - \d{{4}}-\d{{2}}-\d{{2}}$", changelog, re.M
    )


def test_the_readme_module_recipe_deploys_a_clone_at_the_release_tag(tmp_path):
    """The README's recipe with its local-path form: this checkout's HEAD tagged `v<__version__>` in
    a clone (the tag a release makes), a `git clone --branch <tag>` of that, and a host workflow
    whose Snakefile is the README's block with the clone's Snakefile for `github(...)`; a dry run of
    the bundled example through it."""
    from epa import __version__

    git = shutil.which("git")
    if git is None or not (ROOT / ".git").exists():
        pytest.skip("not a git checkout (or no git): nothing to clone")
    tag = f"v{__version__}"

    def run(*args, cwd=tmp_path):
        out = subprocess.run([git, *args], cwd=cwd, capture_output=True, text=True)
        assert out.returncode == 0, out.stderr
        return out.stdout.strip()

    run("clone", "--quiet", "--bare", str(ROOT), "origin.git")
    run("fetch", "--quiet", str(ROOT), "HEAD", cwd=tmp_path / "origin.git")  # HEAD may be detached
    # this tree at the tag (a checkout that has the release tag on an earlier commit moves it)
    run("tag", "--force", tag, "FETCH_HEAD", cwd=tmp_path / "origin.git")
    host = tmp_path / "host"
    host.mkdir()
    run("clone", "--quiet", "--branch", tag, str(tmp_path / "origin.git"), "epica", cwd=host)
    assert run("rev-parse", "HEAD", cwd=host / "epica") == run("rev-parse", "HEAD", cwd=ROOT)
    version = re.search(r'__version__ = "(.+)"', (host / "epica/src/epa/__init__.py").read_text())
    assert version and version.group(1) == __version__
    recipe = re.sub(r"github\([^)]*\)", '"epica/Snakefile"', _readme_module_recipe())
    assert 'snakefile: "epica/Snakefile"' in recipe
    (host / "Snakefile").write_text(
        'configfile: "config.yaml"\n\n'
        + recipe
        + "\n\nrule all:\n    default_target: True\n    input:\n        rules.epica_all.input,\n"
    )
    example = host / "epica/example"
    cfg = {
        "epica": {
            "truth_dir": str(example / "truth"),
            "algorithms_dir": str(example / "algorithms"),
        }
    }
    cfg["epica"]["results_dir"] = "epica_results"
    (host / "config.yaml").write_text(yaml.safe_dump(cfg))
    env = {
        **os.environ,
        "PYTHONPATH": str(host / "epica/src"),
    }  # the release's library
    dry = subprocess.run(
        [sys.executable, "-m", "snakemake", "-n", "--cores", "2", "--quiet", "rules"],
        cwd=host,
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
    )
    said = dry.stdout + dry.stderr
    assert dry.returncode == 0, said[-3000:]
    jobs = dict(re.findall(r"^(epica_\w+)\s+(\d+)$", said, re.M))
    assert {"epica_load", "epica_report", "epica_tables", "epica_figures"} <= set(jobs), said
    assert int(jobs["epica_tables"]) == 1
