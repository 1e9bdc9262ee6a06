"""Configuration: validated against the packaged schema, which is the one source of every default."""

from __future__ import annotations

import copy
from functools import lru_cache
from pathlib import Path

from epa.errors import EpaError

SCHEMA_PATH = Path(__file__).with_name("config.schema.yaml")


@lru_cache(maxsize=1)
def schema() -> dict:
    import yaml

    with open(SCHEMA_PATH, encoding="utf-8") as fh:
        return yaml.safe_load(fh)


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


def resolve(config: dict | None, *, source: str = "config") -> dict:
    """Validate a config and fill in every default; a mistake is one line naming the key."""
    import jsonschema

    cfg = copy.deepcopy(config or {})
    validator = jsonschema.Draft202012Validator(schema())
    errors = sorted(validator.iter_errors(cfg), key=lambda e: list(e.path))
    if errors:
        err = errors[0]
        key = ".".join(str(p) for p in err.path) or "(top level)"
        raise EpaError(f"{key}: {err.message}", path=source)
    return apply_mode(_fill(cfg, schema()), given=config or {})


# What `mode: ov_eval` means for the stages, so that no stage has to test the mode.
OV_EVAL_SETTINGS = {("sync", "estimate_offset"): False, ("sync", "policy"): "ov_eval", ("sync", "max_diff"): 0.02,
                    ("calibrate", "enabled"): False}


def apply_mode(cfg: dict, given: dict) -> dict:
    """Turn ``mode: ov_eval`` into the stage settings it implies; warn where it overrides a given one."""
    if cfg.get("mode") != "ov_eval":
        return cfg
    import logging

    for (section, key), value in OV_EVAL_SETTINGS.items():
        given_section = given.get(section)
        user = given_section.get(key, value) if isinstance(given_section, dict) else value
        if user != value:
            logging.getLogger("epa").warning("mode ov_eval overrides %s.%s: %r -> %r", section, key, user, value)
        cfg[section][key] = value
    return cfg


def defaults() -> dict:
    """Every stage setting at its default (no truth/algorithms folders)."""
    return _fill({}, schema())


GRID_FOLDERS = ("truth_dir", "algorithms_dir")


def load_yaml(path) -> dict:
    """A config file as a mapping (safe-loaded: nothing in it is executed); empty is {}."""
    import yaml

    try:
        with open(path, encoding="utf-8") as fh:
            data = yaml.safe_load(fh)
    except OSError as exc:
        raise EpaError(f"cannot read: {exc.strerror}", path=str(path)) from None
    except yaml.YAMLError as exc:
        raise EpaError(f"not valid YAML: {str(exc).splitlines()[0]}", path=str(path)) from None
    if data is None:
        return {}
    if not isinstance(data, dict):
        raise EpaError(f"a config must be a mapping of settings, not a {type(data).__name__}", path=str(path))
    return data


def check_user_configs(configfiles, overrides: dict | None) -> None:
    """A grid given with ``--configfile`` must name its own folders: the workflow's config/config.yaml
    (the bundled example) is merged underneath, and its folders must never stand in silently."""
    if not configfiles:
        return
    named = set((overrides or {}).keys())
    for path in configfiles:
        named |= load_yaml(path).keys()
    missing = [k for k in GRID_FOLDERS if k not in named]
    if missing:
        raise EpaError(f"names no {' or '.join(missing)} (the bundled example's would be used)",
                       path=", ".join(map(str, configfiles)))
