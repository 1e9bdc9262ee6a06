"""The paper bundle ``results/paper/``: every LaTeX table, every grid figure as PDF and a
``paper.tex`` that \\input's them with the packages they need. It compiles with a plain ``pdflatex``
(``cd results/paper && pdflatex paper.tex``); copy the folder next to a manuscript, or \\input one
table from it. Also the few lines the workflow prints at its end (:func:`where_lines`).
"""

from __future__ import annotations

import shutil
from pathlib import Path

from epa.artifacts import files
from epa.artifacts.stage import folder
from epa.outputs.tables.latex import latex_escape

FOLDER = "paper"
# every package a table or figure needs: T1/utf8 for names and ±, graphicx for the PDFs and
# \resizebox, booktabs for `tables.style: booktabs`, float for [H]
PREAMBLE = r"""\documentclass[10pt]{article}
\usepackage[T1]{fontenc}
\usepackage[utf8]{inputenc}
\usepackage{textcomp}
\usepackage[margin=2cm]{geometry}
\usepackage{graphicx}
\usepackage{booktabs}
\usepackage{float}
"""


def _title(tex_path: Path) -> str:
    """A table's title: the comment on its first line (``% FULL TRAJECTORY ATE ...``)."""
    first = tex_path.read_text(encoding="utf-8").split("\n", 1)[0]
    return first.lstrip("% ").strip() or tex_path.stem


def paper_tex(tables: list[Path], figures: list[Path], captions: dict | None = None) -> str:
    """``paper.tex``: a table environment per table (scaled to the text width), a figure per PDF."""
    captions = captions or {}
    lines = [PREAMBLE.rstrip("\n"), r"\begin{document}", r"\section*{Tables}"]
    for t in tables:
        lines += [
            r"\begin{table}[H]",
            r"\centering",
            r"\caption{" + latex_escape(_title(t).capitalize()) + "}",
            r"\resizebox{\ifdim\width>\linewidth\linewidth\else\width\fi}{!}{\input{tables/"
            + t.name
            + "}}",
            r"\end{table}",
        ]
    lines.append(r"\section*{Figures}")
    for f in figures:
        caption = captions.get(f.stem) or _dataset_caption(f.stem, captions)
        lines += [
            r"\begin{figure}[H]",
            r"\centering",
            r"\includegraphics[width=0.9\linewidth]{figures/" + f.name + "}",
            r"\caption{" + latex_escape(caption) + "}",
            r"\end{figure}",
        ]
    lines += [r"\end{document}", ""]
    return "\n".join(lines)


def _dataset_caption(stem: str, captions: dict) -> str:
    """A per-dataset figure's caption (``trajectories_<dataset>``): its kind's, after the dataset."""
    from epa.outputs.dataset_figures import PREFIXES

    for prefix in PREFIXES:
        if stem.startswith(prefix + "_") and captions.get(prefix):
            return f"{stem[len(prefix) + 1 :]}: {captions[prefix]}"
    return stem.replace("_", " ")


def write_paper(results_dir, captions: dict | None = None) -> list[Path]:
    """Copy every table (``tables/*.tex``, ``comparison.tex``) and grid figure PDF into
    ``results/paper/`` and write ``paper.tex`` over them; returns the files written."""
    results = Path(results_dir)
    out = results / FOLDER
    shutil.rmtree(out, ignore_errors=True)  # a table that is no longer written leaves no copy
    (out / "tables").mkdir(parents=True)
    (out / "figures").mkdir()
    written = []
    sources = sorted((results / "tables").glob("*.tex"))
    if (results / "comparison.tex").is_file():
        sources.append(results / "comparison.tex")
    for src in sources:
        shutil.copyfile(src, out / "tables" / src.name)
        written.append(out / "tables" / src.name)
    for src in sorted((results / "figures").glob("*.pdf")):
        shutil.copyfile(src, out / "figures" / src.name)
        written.append(out / "figures" / src.name)
    tables = [p for p in written if p.parent.name == "tables"]
    figures = [p for p in written if p.parent.name == "figures"]
    files.write_text(out / "paper.tex", paper_tex(tables, figures, captions))
    return [out / "paper.tex", *written]


def figure_captions(caption_dir) -> dict:
    """The grid figures' captions (docs/captions/<name>.rst), as one line of plain text each."""
    caps = {}
    for p in sorted(Path(caption_dir).glob("*.rst")):
        caps[p.stem] = " ".join(p.read_text(encoding="utf-8").split()).replace("``", "")
    return caps


def where_lines(results_dir, per_case: bool = True, report_html: str = "report.html") -> str:
    """The end of a workflow run: where the tables, the comparison, the figures, the paper bundle
    and the HTML report are (the failed cases follow, from :func:`tables.failure_report`)."""
    r = Path(results_dir)
    return "\n".join(
        [
            f"epica: results in {r}/ (provenance.json: inputs, versions, settings; "
            f"`epa verify {r}` regenerates them)",
            f"  tables:     {r}/error_comparison.txt, {r}/tables/*.tex, {r}/summary.csv",
            f"  comparison: {r}/comparison.txt",
            f"  figures:    {r}/figures/ (PNG, PDF)"
            + (
                f"; per case: {r}/cases/<alg>/<dataset>/<run>/{folder('report')}/"
                if per_case
                else ""
            ),
            f"  paper:      {r}/{FOLDER}/paper.tex (cd {r}/{FOLDER} && pdflatex paper.tex)",
            f"  report:     snakemake --report {r}/{report_html}",
        ]
    )
