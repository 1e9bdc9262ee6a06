#!/usr/bin/env bash
# requirements.lock: exact versions with sha256 hashes of epica's runtime dependencies (pyproject.toml's
# [project] dependencies and everything they pull in), resolved on PyPI alone (a local pip config's
# indexes, find-links and constraints are ignored). Needs pip-tools (`pip install pip-tools`), Python 3.11.
# After a change, copy the direct dependencies' versions into envs/epica.yaml;
# tests/test_reproducibility.py checks both against pyproject.toml. See docs/reproducibility.md.
set -euo pipefail
cd "$(dirname "$0")/.."
env -u PIP_FIND_LINKS -u PIP_CONSTRAINT -u PIP_EXTRA_INDEX_URL PIP_CONFIG_FILE=/dev/null \
    pip-compile --generate-hashes --allow-unsafe --strip-extras --no-emit-index-url \
    --no-emit-find-links --index-url https://pypi.org/simple \
    --output-file=requirements.lock pyproject.toml
