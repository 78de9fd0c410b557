"""Write the whole report (``write_report``) and export it for committing (``export_report``)."""

from __future__ import annotations

import json
import logging
from pathlib import Path

from relnav.bench.benchmark import (
    GRID_FILE,
    STORE_FILE,
    GridSpec,
    expand_jobs,
    read_grid,
)
from relnav.bench.report._common import (
    _Ctx,
)
from relnav.bench.report.ablations import _section_ablations
from relnav.bench.report.aggregation import (
    aggregate,
)
from relnav.bench.report.appendix import _section_appendix, _write_all_results
from relnav.bench.report.headline import _section_closing, _section_headline, _section_summary
from relnav.bench.report.normalised import _section_normalised_placeholder
from relnav.bench.report.paper import _section_paper
from relnav.bench.report.robustness import _section_failures, _section_robustness
from relnav.errors import InputError

log = logging.getLogger(__name__)


def write_report(out_dir: str | Path, *, grid: GridSpec | None = None) -> Path:
    """Write ``report.md``, ``tables/*.csv`` and ``figures/*.png`` for a benchmark folder.

    Parameters
    ----------
    out_dir : str or Path
        Benchmark folder (``grid.yaml`` + ``results.sqlite`` from ``relnav benchmark``).
    grid : GridSpec, optional
        Grid to report on (default: the folder's ``grid.yaml``); only its jobs are used.

    Returns
    -------
    Path
        ``report.md``.

    Raises
    ------
    InputError
        Not a benchmark folder, or no job of the grid in the store.
    """
    from relnav.bench.store import ResultsStore

    given = Path(out_dir)  # the folder as the user wrote it, for the regenerate hint
    out = given.resolve()
    if grid is None:
        if not (out / GRID_FILE).is_file():
            raise InputError(f"{out}: no {GRID_FILE}; run `relnav benchmark` into it first")
        grid = read_grid(out)
    jobs = expand_jobs(grid)
    with ResultsStore(out / STORE_FILE, readonly=True) as store:
        rows = store.rows(j.job_id for j in jobs)
        store.to_csv(out / "tables" / "jobs.csv", (j.job_id for j in jobs))
    if not rows:
        raise InputError(f"{out}: no finished job of grid {grid.name!r} in the results store")
    ctx = _Ctx(out, grid, aggregate(rows), [s.label for s in grid.scenarios])
    ctx.tables.append(out / "tables" / "jobs.csv")
    (out / "figures").mkdir(parents=True, exist_ok=True)
    _write_all_results(ctx)
    _section_summary(ctx)
    summary = _section_normalised_placeholder(ctx)
    _section_headline(ctx, summary)
    _section_appendix(ctx)
    ctx.md += summary.pop("__md__", [])
    abl = _section_ablations(ctx)
    verdicts = _section_paper(ctx, summary, abl)
    _section_robustness(ctx)
    _section_failures(ctx)
    _section_closing(ctx, summary, verdicts)
    ctx.md += [
        "## Files",
        "",
        "Tables: " + ", ".join(f"`tables/{p.name}`" for p in ctx.tables) + ".",
        "",
        f"Regenerate with `relnav report {given}`; rerun missing jobs with "
        f"`relnav benchmark <grid.yaml> --out {given}` (finished jobs are skipped).",
        "",
    ]
    report = out / "report.md"
    report.write_text("\n".join(ctx.md).replace("\n\n\n", "\n\n"))
    (out / "report_summary.json").write_text(
        json.dumps({"verdicts": verdicts, "figures": [p.name for p in ctx.figures]}, indent=2)
        + "\n"
    )
    log.info("wrote %s (%d tables, %d figures)", report, len(ctx.tables), len(ctx.figures))
    return report


def export_report(out_dir: str | Path, dest: str | Path, *, colors: int = 256) -> Path:
    """Copy ``report.md`` and its figures to ``dest`` (markdown + small PNGs, e.g. for git).

    The PNGs are re-encoded with a ``colors``-entry palette (Pillow), typically 3–4× smaller
    with no visible change for line plots. CSV tables stay in the benchmark folder.

    Returns
    -------
    Path
        ``dest/report.md``.
    """
    from PIL import Image

    src = Path(out_dir)
    md = src / "report.md"
    if not md.is_file():
        raise InputError(f"{src}: no report.md (run `relnav report {src}` first)")
    dst = Path(dest)
    (dst / "figures").mkdir(parents=True, exist_ok=True)
    text = md.read_text()
    for png in sorted((src / "figures").glob("*.png")):
        if f"figures/{png.name}" not in text:
            continue
        with Image.open(png) as im:
            im.convert("RGB").quantize(colors=colors, dither=Image.Dither.NONE).save(
                dst / "figures" / png.name, optimize=True
            )
    text = text.replace("Tables: `tables/", "Tables (in the benchmark folder): `tables/")
    (dst / "report.md").write_text(text)
    return dst / "report.md"
