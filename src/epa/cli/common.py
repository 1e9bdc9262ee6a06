"""What several commands name: the report stage and its folder in a case folder."""

from epa.artifacts.stage import folder

REPORT_STAGE = "report"
REPORT = folder(REPORT_STAGE)  # the report stage's folder in a case folder
