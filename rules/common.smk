# Parse-time setup: resolved settings (schema defaults filled in) and the discovered cases.
import os

import epa
from epa import cases as epa_cases, settings as epa_settings

EPA = epa_settings.resolve(config, source="config")
EPA_VERSION = epa.__version__
RESULTS = EPA["results_dir"]
CASE = os.path.join(RESULTS, "cases", "{algorithm}", "{dataset}", "{run}")
TRUTH, CASES = epa_cases.discover(EPA["truth_dir"], EPA["algorithms_dir"])
ESTIMATES = {c.key: str(c.estimate) for c in CASES}
DATASETS = sorted({c.dataset for c in CASES})
TABLE_NAMES = [
    "ate", "rpe_distance", "drift_rate", "rpe_time_1s", "success_rate",
    "valid_ate", "valid_rpe_distance", "valid_drift_rate", "valid_rpe_time_1s",
]
TABLE_OUTPUTS = [f"{RESULTS}/error_comparison.txt", f"{RESULTS}/summary.csv"] + [
    f"{RESULTS}/tables/{name}.tex" for name in TABLE_NAMES
]


wildcard_constraints:
    algorithm="[^/]+",
    dataset="[^/]+",
    run="[^/]+",


def case_files(path):
    """One path per discovered case, for the tables rule."""
    return [path.format(algorithm=c.algorithm, dataset=c.dataset, run=c.run) for c in CASES]
