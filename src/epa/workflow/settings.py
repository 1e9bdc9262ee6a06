"""Configuration: validated against the packaged schema, which is the one source of every default."""

from __future__ import annotations

import copy
import hashlib
import json
import math
from functools import lru_cache
from pathlib import Path

from epa.core.errors import EpaError

SCHEMA_PATH = Path(__file__).with_name("config.schema.yaml")
# The schema as JSON, with the sha256 of the YAML it was written from (write_schema_json): read in
# 0.2 ms where PyYAML's import and libyaml's load took 30-40 ms of every `epa eval`. A JSON that does
# not match the YAML is never used (the YAML is read instead); tests/test_config_reference.py fails
# until it is rewritten.
SCHEMA_JSON = SCHEMA_PATH.with_suffix(".json")


@lru_cache(maxsize=1)
def schema() -> dict:
    source = SCHEMA_PATH.read_bytes()
    cached = _schema_json(hashlib.sha256(source).hexdigest())
    return cached if cached is not None else _schema_yaml(source)


def _schema_yaml(source: bytes) -> dict:
    import yaml

    # libyaml's loader where PyYAML has it: 0.2 s less in every process that reads a config
    return yaml.load(source, Loader=getattr(yaml, "CSafeLoader", yaml.SafeLoader))  # noqa: S506


def _schema_json(sha256: str) -> dict | None:
    """The schema from SCHEMA_JSON when that was written from the YAML whose hash is ``sha256``."""
    try:
        with open(SCHEMA_JSON, encoding="utf-8") as fh:
            cached = json.load(fh)
    except (OSError, ValueError):
        return None
    return cached["schema"] if cached.get("yaml_sha256") == sha256 else None


def schema_json_text() -> str:
    """What SCHEMA_JSON holds: the YAML's hash and the document it loads to."""
    source = SCHEMA_PATH.read_bytes()
    cached = {"yaml_sha256": hashlib.sha256(source).hexdigest(), "schema": _schema_yaml(source)}
    return json.dumps(cached, indent=1, ensure_ascii=False) + "\n"


def write_schema_json() -> None:
    """Rewrite SCHEMA_JSON from the YAML (after editing the schema: ``python -m epa.workflow.settings``)."""
    SCHEMA_JSON.write_text(schema_json_text(), encoding="utf-8")


def _fill(value, sch: dict):
    if sch.get("type") == "object" or "properties" in sch:
        value = {} if value is None else value
        for key, sub in sch.get("properties", {}).items():
            if key not in value and "default" in sub:
                value[key] = copy.deepcopy(sub["default"])
            if key in value:
                value[key] = _fill(value[key], sub)
    elif sch.get("type") == "array" and isinstance(value, list) and "items" in sch:
        value = [_fill(v, sch["items"]) for v in value]
    return value


def defaults() -> dict:
    """Every setting at its default (the schema's), the folders aside."""
    return _fill({}, schema())


def _non_finite(value, key: str = "") -> str | None:
    """The key of the first number that is nan or infinite (the schema's bounds let them through:
    nan compares false with every bound, inf passes any minimum)."""
    if isinstance(value, dict):
        for k, v in value.items():
            found = _non_finite(v, f"{key}.{k}" if key else str(k))
            if found:
                return found
    elif isinstance(value, list):
        for k, v in enumerate(value):
            found = _non_finite(v, f"{key}.{k}")
            if found:
                return found
    elif isinstance(value, float) and not math.isfinite(value):
        return key
    return None


# A setting whose schema says no more than these can take any value of its type; "default" and
# "description" constrain nothing.
_FREE_OF = {"type", "default", "description"}


def _plainly_valid(value, sch: dict) -> bool:
    """Whether ``value`` is valid under ``sch`` without a validator: an object of known keys, each
    at its default (same type) or a boolean where the schema asks for just a boolean, or one of the
    grid folders a non-empty string. Anything else (also anything this cannot tell) is False and
    goes to jsonschema: ``epa eval`` with its defaults then spares jsonschema's import (about 0.1 s,
    half the command's start)."""
    if not isinstance(value, dict) or sch.get("type") != "object" or "properties" not in sch:
        return False
    props = sch["properties"]
    for key, v in value.items():
        sub = props.get(key)
        if sub is None:
            return False
        if key in GRID_FOLDERS and sub.get("type") == "string":
            if not (isinstance(v, str) and v and set(sub) <= _FREE_OF | {"minLength"}):
                return False
        elif isinstance(v, dict):
            if not _plainly_valid(v, sub):
                return False
        elif isinstance(v, bool) and sub.get("type") == "boolean" and set(sub) <= _FREE_OF:
            continue
        elif "default" not in sub or type(v) is not type(sub["default"]) or v != sub["default"]:
            return False
    return all(key in value for key in sch.get("required", []))


def resolve(config: dict | None, *, source: str = "config") -> dict:
    """Validate a config and fill in every default; a mistake is one line naming the key."""
    cfg = copy.deepcopy(config or {})
    bad = _non_finite(cfg)
    if bad:
        value = _at(cfg, bad.split("."))
        raise EpaError(f"{bad}: {value} is not a finite number", path=source)
    errors = [] if _plainly_valid(cfg, schema()) else _schema_errors(cfg)
    if errors:
        err = _deepest(errors[0])
        key = ".".join(str(p) for p in err.absolute_path) or "(top level)"
        what = err.message
        if err.validator == "not":
            what = f"{err.instance!r} is not allowed: {err.schema.get('description', '')}".rstrip(
                ": "
            )
        raise EpaError(f"{key}: {what}", path=source)
    cfg = apply_mode(_fill(cfg, schema()), given=config or {})
    for problem in (check_inputs(cfg), check_first_n(cfg), check_crop(cfg)):
        if problem:
            raise EpaError(problem, path=source)
    sources = cfg["sources"]
    for key, src in [("reference", sources.get("reference") or {})] + [
        (f"datasets.{name}", src or {}) for name, src in (sources.get("datasets") or {}).items()
    ]:
        if src.get("metric_scale") is not None:
            raise EpaError(
                f"sources.{key}.metric_scale: a reference's scale is the metre; metric_scale declares"
                " an estimate's (sources.algorithms.<algorithm>.metric_scale)",
                path=source,
            )
    if cfg["report"]["rerun"]:
        from epa.outputs import recording

        if not recording.available():  # refused before any case runs, not once per case
            raise EpaError(recording.INSTALL_HINT, path=source)
    return cfg


def _deepest(err):
    """Of a value valid under none of a setting's forms (a list of lengths or a word): the error of
    the form it was meant as (a list's bad item), not "is not valid under any of the given schemas"
    (a wrong word: the words it may be)."""
    if err.validator != "anyOf" or not err.context:
        return err
    kinds: dict[type, str] = {list: "array", str: "string"}
    kind = kinds.get(type(err.instance))
    branches = [b.get("type") for b in err.validator_value]
    if kind in branches:  # the form its type says it was meant as: that form's first error
        meant = [e for e in err.context if e.relative_schema_path[0] == branches.index(kind)]
        if meant and kind == "array":
            return _deepest(meant[0])
    words = [w for b in err.validator_value for w in b.get("enum", ())]
    if words:
        err.message = f"{err.instance!r} is neither a list of numbers nor one of {', '.join(words)}"
    return err


def _schema_errors(cfg: dict) -> list:
    import jsonschema

    validator = jsonschema.Draft202012Validator(schema())
    return sorted(validator.iter_errors(cfg), key=lambda e: list(e.path))


def _at(node, keys: list):
    for k in keys:
        node = node[int(k)] if isinstance(node, list) else node[k]
    return node


def _schema_at(keys: list) -> dict:
    """The schema of one key path (object properties, additionalProperties, array items, $refs)."""
    root = schema()
    sch = root
    for k in keys:
        if "$ref" in sch:
            sch = _pointer(root, sch["$ref"])
        if "anyOf" in sch:  # a list or a word (metrics.segments): the branch that has the key
            digit = isinstance(k, int) or (isinstance(k, str) and k.isdigit())
            sch = next((b for b in sch["anyOf"] if ("items" in b) == digit), sch["anyOf"][0])
        if isinstance(k, int) or (isinstance(k, str) and k.isdigit() and "items" in sch):
            sch = sch.get("items", {})
        elif k in sch.get("properties", {}):
            sch = sch["properties"][k]
        elif isinstance(sch.get("additionalProperties"), dict):
            sch = sch["additionalProperties"]
        else:
            return {}
    if "$ref" in sch:
        sch = _pointer(root, sch["$ref"])
    if "anyOf" in sch:  # the leaf's types: every branch's
        types = [b.get("type") for b in sch["anyOf"]]
        return {**sch, "type": [t for t in types if isinstance(t, str)]}
    return sch


def _pointer(root: dict, ref: str) -> dict:
    """The schema a local ``$ref`` (``#/$defs/source``, ``#/properties/sync``) points at."""
    node = root
    for part in ref.removeprefix("#/").split("/"):
        node = node[part]
    return node


YAML_TRUE = ("true", "yes", "on")
YAML_FALSE = ("false", "no", "off")


def coerce_overrides(config: dict, overrides: dict | None) -> dict:
    """Snakemake reads ``--config key={...}`` with YAML's BaseLoader: every nested scalar is a string
    (``report={"per_case": false}`` gives ``'false'``). The keys given on the command line are turned
    back into what the schema expects: a YAML boolean word for a boolean key, a number for a number
    key, ``null`` where null is allowed. Nothing else is touched (a config file's quoted ``"false"``
    stays an error)."""
    cfg = copy.deepcopy(config)

    def walk(given, node, keys):
        if isinstance(given, dict) and isinstance(node, dict):
            for k, v in given.items():
                if k in node:
                    node[k] = walk(v, node[k], keys + [k])
            return node
        if isinstance(given, list) and isinstance(node, list) and len(given) == len(node):
            return [walk(g, n, keys + [str(i)]) for i, (g, n) in enumerate(zip(given, node))]
        if not isinstance(node, str):
            return node
        types = _schema_at(keys).get("type")
        types = types if isinstance(types, list) else [types]
        word = node.strip().lower()
        if "boolean" in types and word in YAML_TRUE + YAML_FALSE:
            return word in YAML_TRUE
        if "null" in types and word in ("null", "~", ""):
            return None
        if "integer" in types or "number" in types:
            for parse in (int, float):  # as YAML reads it: 8 is an int, 8.5 a float
                try:
                    return parse(word)
                except ValueError:
                    pass
        return node

    for k, v in (overrides or {}).items():
        if k in cfg:
            cfg[k] = walk(v, cfg[k], [k])
    return cfg


# What `mode: ov_eval` and `mode: rpg` mean for the stages, so that no stage has to test the mode
# for these (the align and metrics stages test mode rpg for rpg's arithmetic and statistics).
# Both tools associate by their own rule within 0.02 s, with no offset estimate and no extrinsic.
MODE_SETTINGS = {
    mode: {
        ("sync", "estimate_offset"): False,
        ("sync", "policy"): mode,
        ("sync", "max_diff"): 0.02,
        ("calibrate", "enabled"): False,
    }
    for mode in ("ov_eval", "rpg")
}


def apply_mode(cfg: dict, given: dict) -> dict:
    """Turn ``mode: ov_eval`` or ``mode: rpg`` into the stage settings it implies; warn where it
    overrides a given one."""
    implied = MODE_SETTINGS.get(cfg.get("mode") or "")
    if implied is None:
        return cfg
    import logging

    for (section, key), value in implied.items():
        given_section = given.get(section)
        user = given_section.get(key, value) if isinstance(given_section, dict) else value
        if user != value:
            logging.getLogger(__name__).warning(
                "mode %s overrides %s.%s: %r -> %r", cfg["mode"], section, key, user, value
            )
        cfg[section][key] = value
    return cfg


def check_inputs(cfg: dict) -> str | None:
    """What is wrong with the way the config names its inputs (None: nothing): the OpenVINS
    layout's two folders, both patterns, or a sheet; exactly one of them."""
    inputs = cfg["inputs"]
    ways = {
        "truth_dir/algorithms_dir": {k: cfg.get(k) for k in GRID_FOLDERS},
        "inputs.reference/inputs.estimate": {
            f"inputs.{k}": inputs.get(k) for k in ("reference", "estimate")
        },
        "inputs.sheet": {"inputs.sheet": inputs.get("sheet")},
    }
    given = [way for way, keys in ways.items() if any(keys.values())]
    if len(given) > 1:
        return f"{given[0]} and {given[1]} both name the inputs: keep one way"
    if not given:
        return (
            "names no inputs: truth_dir and algorithms_dir, inputs.reference and inputs.estimate,"
            " or inputs.sheet"
        )
    keys = ways[given[0]]
    missing = [k for k, v in keys.items() if not v]
    if missing:
        present = next(k for k, v in keys.items() if v)
        return f"{present} without {missing[0]}: give both"
    if inputs["datasets"] and "inputs.estimate" not in keys:
        return "inputs.datasets maps the estimate patterns' {dataset}: it needs inputs.estimate"
    return None


def check_first_n(cfg: dict) -> str | None:
    """What is wrong with ``align.first_n`` under the mode and method (None: nothing). Fewer than 3
    poses determine no rotation, so 1 and 2 are rpg's alone: 1 is its first-pose alignment (se3,
    posyaw), which its sim3 refuses."""
    n, method = cfg["align"]["first_n"], cfg["align"]["method"]
    if n in (1, 2) and cfg["mode"] != "rpg":
        return (
            f"align.first_n: {n} is not allowed: at least 3 poses determine a rotation (-1 = all;"
            " 1 and 2 are rpg's, in mode rpg only)"
        )
    if n == 1 and method == "sim3":
        return "align.first_n: 1 is not allowed with align.method sim3: rpg's sim3 needs 2 or more"
    return None


def check_crop(cfg: dict) -> str | None:
    """What is wrong with the crop window (None: nothing)."""
    crop = cfg["crop"]
    if crop["start"] is not None and crop["end"] is not None and crop["end"] <= crop["start"]:
        return f"crop.end ({crop['end']}) must be after crop.start ({crop['start']})"
    return None


GRID_FOLDERS = ("truth_dir", "algorithms_dir")


@lru_cache(maxsize=1)
def _strict_loader():
    """PyYAML's safe loader, except that a key given twice is an error (PyYAML keeps the last one)."""
    import yaml

    class StrictLoader(yaml.SafeLoader):
        def construct_mapping(self, node, deep=False):
            seen = set()
            for key_node, _ in node.value:
                key = self.construct_object(key_node, deep=deep)
                if key in seen:
                    raise EpaError(
                        f"{key!r} is given twice (the second would silently win)",
                        line=key_node.start_mark.line + 1,
                    )
                seen.add(key)
            return super().construct_mapping(node, deep=deep)

    return StrictLoader


def load_yaml(path) -> dict:
    """A config file as a mapping (safe-loaded: nothing in it is executed); empty is {}."""
    import yaml

    try:
        with open(path, encoding="utf-8") as fh:
            data = yaml.load(fh, Loader=_strict_loader())  # noqa: S506 - a SafeLoader subclass
    except EpaError as exc:
        raise EpaError(exc.message, path=str(path), line=exc.line) from None
    except OSError as exc:
        raise EpaError(f"cannot read: {exc.strerror}", path=str(path)) from None
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        what = getattr(exc, "problem", None) or str(exc).splitlines()[0]
        raise EpaError(
            f"not valid YAML: {what}", path=str(path), line=mark.line + 1 if mark else None
        ) from None
    if data is None:
        return {}
    if not isinstance(data, dict):
        raise EpaError(
            f"a config must be a mapping of settings, not a {type(data).__name__}", path=str(path)
        )
    return data


def from_configfile(path) -> dict:
    """A grid's config file, validated, every default filled in (errors name the file and key)."""
    return resolve(load_yaml(path), source=str(path))


def check_user_configs(configfiles, overrides: dict | None) -> set[str]:
    """A grid given with ``--configfile`` must name its own inputs (its folders, or an ``inputs``
    section): the workflow's config/config.yaml (the bundled example) is merged underneath, and its
    folders must never stand in silently. Returns the top-level keys the user's files name."""
    named = set((overrides or {}).keys())
    if not configfiles:
        return named
    for path in configfiles:
        named |= load_yaml(path).keys()
    missing = [k for k in GRID_FOLDERS if k not in named]
    if missing and "inputs" not in named:
        raise EpaError(
            f"names no {' or '.join(missing)} (the bundled example's would be used)",
            path=", ".join(map(str, configfiles)),
        )
    return named


def without_bundled_folders(config: dict, named: set[str]) -> dict:
    """The merged config without the bundled example's folders where the user's config names its
    inputs by an ``inputs`` section and names no folder (the example's would clash with it)."""
    if "inputs" not in named or named & set(GRID_FOLDERS):
        return config
    return {k: v for k, v in config.items() if k not in GRID_FOLDERS}


if __name__ == "__main__":
    write_schema_json()
