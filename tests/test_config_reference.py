"""The documentation is current: config/README.md is what scripts/config_reference.py writes from the
schema, and every relative link in the README, config/README.md and docs/*.md reaches a file (and, with
``#anchor``, a heading of it)."""

from __future__ import annotations

import importlib.util
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
GENERATOR = ROOT / "scripts" / "config_reference.py"


def _generator():
    spec = importlib.util.spec_from_file_location("config_reference", GENERATOR)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_config_reference_is_current():
    gen = _generator()
    assert gen.SCHEMA.exists(), (
        f"{gen.SCHEMA} not found: update SCHEMA at the top of {GENERATOR.name}"
    )
    current = gen.OUTPUT.read_text(encoding="utf-8")
    assert current == gen.render(), f"config/README.md is stale: run `{gen.COMMAND}`"


def test_config_reference_lists_every_default():
    gen = _generator()
    text = gen.OUTPUT.read_text(encoding="utf-8")
    schema = gen.load_schema()
    for section, sub in schema["properties"].items():
        for key, prop in sub.get("properties", {}).items():
            if "default" in prop:
                assert f"| `{section}.{key}" in text, (
                    f"{section}.{key} missing: run `{gen.COMMAND}`"
                )
    assert "snakemake --cores 2 --configfile my.yaml" in text


LINK = re.compile(r"!?\[[^\]]*\]\(([^)\s]+)\)")
PAGES = [ROOT / "README.md", ROOT / "config" / "README.md", *sorted((ROOT / "docs").glob("*.md"))]


def _anchors(page: Path) -> set[str]:
    """GitHub's heading anchors: lower case, punctuation dropped, spaces as hyphens."""
    out = set()
    in_code = False
    for line in page.read_text(encoding="utf-8").splitlines():
        if line.startswith("```"):
            in_code = not in_code
        if in_code or not line.startswith("#"):
            continue
        title = line.lstrip("#").strip().lower()
        out.add(re.sub(r"[^\w\- ]", "", title).replace(" ", "-"))
    return out


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(ROOT)))
def test_relative_links_resolve(page):
    text = re.sub(r"```.*?```", "", page.read_text(encoding="utf-8"), flags=re.DOTALL)
    broken = []
    for target in LINK.findall(text):
        if re.match(r"[a-z][a-z0-9+.-]*:", target):  # https:, mailto:, ...
            continue
        path, _, anchor = target.partition("#")
        dest = (page.parent / path).resolve() if path else page
        missing_anchor = bool(anchor) and dest.suffix == ".md" and anchor not in _anchors(dest)
        if not dest.exists() or missing_anchor:
            broken.append(target)
    assert not broken, f"{page.relative_to(ROOT)}: broken links {broken}"


def test_schema_reads_the_same_with_libyaml():
    """The schema is read by libyaml's loader where PyYAML has it (0.2 s a process): the same
    document as PyYAML's pure-Python safe loader."""
    import yaml

    from epa.workflow import settings

    with open(settings.SCHEMA_PATH, encoding="utf-8") as fh:
        assert settings._schema_yaml(settings.SCHEMA_PATH.read_bytes()) == yaml.safe_load(fh)


def test_schema_json_is_current():
    """config.schema.json is what the YAML loads to (types and key order too: compared by repr), so
    that `epa eval` reads it instead of importing PyYAML; after editing the schema, rewrite it with
    ``python -m epa.workflow.settings``."""
    from epa.workflow import settings

    assert settings.SCHEMA_JSON.read_text(encoding="utf-8") == settings.schema_json_text(), (
        "src/epa/workflow/config.schema.json is stale: python -m epa.workflow.settings"
    )
    schema = settings._schema_yaml(settings.SCHEMA_PATH.read_bytes())
    assert repr(settings.schema()) == repr(schema)


def test_schema_json_of_another_yaml_is_not_used(monkeypatch, tmp_path):
    """A JSON written from another version of the YAML is ignored: the YAML is read."""
    from epa.workflow import settings

    stale = tmp_path / "config.schema.json"
    stale.write_text('{"yaml_sha256": "0", "schema": {"stale": true}}', encoding="utf-8")
    monkeypatch.setattr(settings, "SCHEMA_JSON", stale)
    settings.schema.cache_clear()
    try:
        assert "stale" not in settings.schema() and "properties" in settings.schema()
    finally:
        settings.schema.cache_clear()
