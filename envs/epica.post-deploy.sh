#!/usr/bin/env bash
# Snakemake runs this inside the new environment, from the working directory: install epica from
# the checkout there (EPICA_SOURCE names another one) without touching the dependencies above.
set -euo pipefail
python -m pip install --no-deps "${EPICA_SOURCE:-.}"
