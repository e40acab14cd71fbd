"""Static HTML pages of runs: one per output folder (``report.html``) and one comparing runs.

A page is plain HTML with its style inline and no script, so it opens from disk in any
browser without a server. Figures are ``<img>`` elements with *relative* links to the PNGs
beside the page (a run's page) or in the run folders (a comparison page): the PNGs are in the
folder already, so embedding them as base64 would store every picture twice and make the
page a third larger than the images; a folder moved or copied as a whole keeps its page
working. Every text that comes from data (names, descriptions, config values, metric keys)
goes through :func:`html.escape`.

Nothing here imports matplotlib: the pages are built from what a run folder holds
(``metrics.json``, ``config.json``, the images) and a few strings. What reading the data
file did (``metrics.json``'s ``"reading"``) is rebuilt as the
:class:`~slamkit.datasets.reading.ReadingSummary` the run printed, so the page says it in the
same words.
"""

from __future__ import annotations

import html
import json
import os
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from slamkit.datasets.reading import FEW_DROPPED, MAX_DROPPED_SHARE, ReadingSummary
from slamkit.errors import InputError
from slamkit.eval.glossary import GROUPS, MetricRow, format_number, metric_rows

__all__ = [
    "FIGURE_CAPTIONS",
    "FIGURE_ORDER",
    "RunPage",
    "compare_html",
    "flatten_metrics",
    "order_figures",
    "read_run_folder",
    "run_html",
    "write_compare_page",
    "write_run_page",
]

FIGURE_ORDER = (
    "trajectory.png",
    "map.png",
    "loops.png",
    "errors.png",
    "particles.png",
    "nees.png",
    "nis.png",
    "relation_errors.png",
    "graph.png",
)
"""The order figures appear in on a page; other images follow by name."""

FIGURE_CAPTIONS = {
    "trajectory.png": "The estimated path (blue) against the true one (dashed black) where "
    "there is a truth, else coloured by the time since the start so a revisit shows; loop "
    "closures in red. Start: green circle, end: square.",
    "map.png": "The map the run built or localized in, with the estimated path over it; "
    "the scale bar gives metres. Walls that appear twice, offset, are a place the run did "
    "not recognise.",
    "map_view.png": "The occupancy map in metres with the poses of the scans.",
    "loops.png": "The optimised keyframes over the map and, in red, the loop closures kept: "
    "each joins two visits of one place. Their number is in the title.",
    "errors.png": "x, y and heading error against time. With a covariance, the error as "
    "estimated and the ±3σ band: the error should stay inside it. Without one, the error "
    "after the alignment of the headline ATE (the title says which).",
    "particles.png": "The particle cloud at a few moments, each panel zoomed to its cloud, "
    "with the true pose: a cloud that shrinks round the truth has found the robot.",
    "nees.png": "NEES against time with its 95 % band: above the band the estimator is "
    "over-confident, below it too cautious.",
    "nis.png": "NIS of the updates against time with its 95 % band: innovations larger than "
    "the filter predicts lie above it.",
    "relation_errors.png": "The error of each reference relation, translation and rotation, "
    "along the run: spikes are places where the map is locally wrong.",
    "graph.png": "The pose graph: keyframes and their edges.",
    "animation.gif": "The run as it went, one frame per moment, the current pose an arrow.",
}
"""What each figure shows and how to read it (the page's captions; others get their name)."""

HEADLINE = (
    "ate.rmse",
    "ate_unaligned.rmse",
    "final_position_error",
    "landmarks.rmse",
    "gps.rmse",
    "runtime.total_seconds",
)
"""Metrics (flattened keys) repeated at the top of a run's page, when the run has them; their
labels and units from :mod:`slamkit.eval.glossary`."""

_IMAGE_SUFFIXES = (".png", ".gif", ".svg", ".jpg", ".jpeg")

_STYLE = """
body { font-family: system-ui, sans-serif; margin: 1.5em auto; max-width: 1200px;
       color: #222; background: #fff; padding: 0 1em; }
h1 { font-size: 1.5em; } h2 { font-size: 1.2em; margin-top: 1.6em;
     border-bottom: 1px solid #ccc; }
table { border-collapse: collapse; font-size: 0.9em; }
th, td { border: 1px solid #ccc; padding: 0.25em 0.6em; text-align: left; vertical-align: top; }
td.num { text-align: right; font-variant-numeric: tabular-nums; }
th { background: #f0f0f0; }
pre { background: #f6f6f6; padding: 0.8em; overflow-x: auto; font-size: 0.85em; }
figure { margin: 0.5em 0.5%; display: inline-block; vertical-align: top; max-width: 48%; }
.runs figure { max-width: 100%; }
figure img { max-width: 100%; border: 1px solid #ddd; }
figcaption { font-size: 0.85em; color: #555; }
.runs { display: grid; grid-template-columns: repeat(auto-fit, minmax(360px, 1fr)); gap: 1em; }
.muted { color: #777; }
table.metrics { width: 100%; table-layout: fixed; }
table.metrics th:nth-child(1) { width: 30%; } table.metrics th:nth-child(2) { width: 8em; }
table.metrics th:nth-child(3) { width: 3.5em; } table.metrics th { font-weight: normal; }
table.metrics tr:first-child th { font-weight: bold; }
table.metrics td.muted { font-size: 0.9em; }
details summary { cursor: pointer; color: #555; margin: 0.3em 0; }
#verdict.consistent { color: #1b6e1b; }
#verdict.doubtful { color: #8a5a00; }
"""


@dataclass(frozen=True)
class RunPage:
    """What a run's page shows. ``figures`` and ``files`` are names inside ``folder``;
    ``timings`` are wall-clock seconds by phase (``load``, ``run``, ``evaluate``, …)."""

    folder: Path
    estimator: str
    dataset: str
    metrics: Mapping[str, Any] = field(default_factory=dict)
    config: Mapping[str, Any] = field(default_factory=dict)
    figures: tuple[str, ...] = ()
    files: tuple[str, ...] = ()
    estimator_description: str = ""
    dataset_description: str = ""
    timings: Mapping[str, float] = field(default_factory=dict)
    reading: ReadingSummary | None = None
    """What reading the data file dropped and repaired (``metrics.json``'s ``"reading"``;
    None: simulated data)."""

    @property
    def title(self) -> str:
        return f"{self.estimator} on {self.dataset}"


def _read_json(path: Path) -> dict[str, Any]:
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise InputError(f"{path}: cannot read ({exc.strerror or exc})") from exc
    except json.JSONDecodeError as exc:
        raise InputError(f"{path}: not JSON (line {exc.lineno}: {exc.msg})") from exc
    if not isinstance(data, dict):
        raise InputError(f"{path}: expected a JSON object, got {type(data).__name__}")
    return data


def _figure_key(name: str) -> tuple[int, str]:
    return (FIGURE_ORDER.index(name) if name in FIGURE_ORDER else len(FIGURE_ORDER), name)


def order_figures(names: Iterable[str]) -> tuple[str, ...]:
    """The image names among ``names`` in page order (:data:`FIGURE_ORDER`, then by name)."""
    imgs = [n for n in names if n.lower().endswith(_IMAGE_SUFFIXES) and not n.startswith(".")]
    return tuple(sorted(imgs, key=_figure_key))


def read_run_folder(
    folder: str | os.PathLike[str],
    *,
    estimator_description: str = "",
    dataset_description: str = "",
    timings: Mapping[str, float] | None = None,
) -> RunPage:
    """The page of the run written to ``folder`` (by ``slamkit run``): its
    ``metrics.json``, ``config.json`` and images. Raises
    :class:`~slamkit.errors.InputError` when the folder is not a run's output folder."""
    root = Path(folder)
    if not root.is_dir():
        raise InputError(f"{root}: not a folder")
    if not (root / "metrics.json").is_file():
        raise InputError(f"{root}: not a run's output folder (no metrics.json)")
    metrics = _read_json(root / "metrics.json")
    config = _read_json(root / "config.json") if (root / "config.json").is_file() else {}
    names = sorted(p.name for p in root.iterdir() if p.is_file())
    figures = tuple(  # an SVG copy of a PNG is linked from the file list, not shown twice
        n for n in order_figures(names) if not (n.endswith(".svg") and n[:-4] + ".png" in names)
    )
    est = config.get("estimator", {})
    ds = config.get("dataset", {})
    reading = metrics.get("reading")
    if reading is not None and not isinstance(reading, Mapping):
        raise InputError(f"{root / 'metrics.json'}: reading: expected a record, got {reading!r}")
    return RunPage(
        folder=root,
        estimator=str(metrics.get("estimator") or est.get("name", "?")),
        dataset=str(metrics.get("dataset") or ds.get("name", "?")),
        metrics=metrics,
        config=config,
        figures=figures,
        files=tuple(names),
        estimator_description=estimator_description,
        dataset_description=dataset_description,
        timings=dict(timings or {}),
        reading=None if reading is None else ReadingSummary.from_dict(reading),
    )


# --------------------------------------------------------------------------------------------
# metrics as rows
# --------------------------------------------------------------------------------------------


def _format_value(value: Any) -> str:
    """A value of the page's tables: numbers, flags, text and short lists as the glossary
    shows them (:func:`~slamkit.eval.glossary.format_number`), anything else as JSON."""
    if value is None or isinstance(value, (bool, int, float, str, list, tuple)):
        return format_number(value)
    return json.dumps(value)


def flatten_metrics(metrics: Mapping[str, Any], prefix: str = "") -> dict[str, str]:
    """``metrics.json`` as ``{dotted key: formatted value}`` in the file's order: nested
    records flattened (``ate.rmse``), a metric that does not apply as ``skipped: reason``,
    long lists as their length, what reading the data did (``"reading"``) as one row of
    words (its reasons are phrases, not keys). ``estimator`` and ``dataset`` are left out
    (they head the page)."""
    rows: dict[str, str] = {}
    for key, value in metrics.items():
        if not prefix and key in ("estimator", "dataset"):
            continue
        name = f"{prefix}{key}"
        if not prefix and key == "reading" and isinstance(value, Mapping):
            rows[name] = _reading_row(value)
        elif isinstance(value, Mapping):
            if set(value) == {"skipped"}:
                rows[name] = f"skipped: {value['skipped']}"
            else:
                rows.update(flatten_metrics(value, f"{name}."))
        else:
            rows[name] = _format_value(value)
    return rows


def _in_words(key: str) -> str:
    """A dotted diagnostics key in words: ``loops_rejected.low_score`` → ``loops rejected ›
    low score`` (a reason after a colon kept: ``refine:degenerate`` → ``refine: degenerate``)."""
    return " › ".join(part.replace("_", " ").replace(":", ": ") for part in key.split("."))


def _reading_row(reading: Mapping[str, Any]) -> str:
    """``"used of records scans, N dropped, M repaired, K ignored"`` of a ``"reading"``
    record."""
    try:
        summary = ReadingSummary.from_dict(reading)
    except InputError:
        return "malformed"
    text = f"{summary.used} of {summary.records} {summary.what}"
    for verb, counts in (
        ("dropped", summary.dropped),
        ("repaired", summary.repaired),
        ("ignored", summary.ignored),
    ):
        if counts:
            text += f", {sum(counts.values())} {verb}"
    if summary.notes:
        text += f", {len(summary.notes)} note{'s' if len(summary.notes) > 1 else ''}"
    return text


# --------------------------------------------------------------------------------------------
# HTML
# --------------------------------------------------------------------------------------------


def _e(text: object) -> str:
    return html.escape(str(text), quote=True)


def _page(title: str, body: Sequence[str]) -> str:
    return "\n".join(
        [
            "<!DOCTYPE html>",
            '<html lang="en">',
            "<head>",
            '<meta charset="utf-8">',
            '<meta name="viewport" content="width=device-width, initial-scale=1">',
            f"<title>{_e(title)}</title>",
            f"<style>{_STYLE}</style>",
            "</head>",
            "<body>",
            *body,
            "</body>",
            "</html>",
            "",
        ]
    )


def _is_number(text: str) -> bool:
    try:
        float(text.replace(",", ""))
    except ValueError:
        return False
    return True


def _table(header: Sequence[str] | None, rows: Iterable[Sequence[str]], css_id: str) -> str:
    out = [f'<table id="{_e(css_id)}">']
    if header:
        out.append("<tr>" + "".join(f"<th>{_e(h)}</th>" for h in header) + "</tr>")
    for row in rows:
        cells = [f"<th>{_e(row[0])}</th>"]
        cells += [
            f'<td class="num">{_e(c)}</td>' if _is_number(c) else f"<td>{_e(c)}</td>"
            for c in row[1:]
        ]
        out.append("<tr>" + "".join(cells) + "</tr>")
    out.append("</table>")
    return "\n".join(out)


def _figure(src: str, caption: str, width: str = "", explanation: str = "") -> str:
    style = f' style="width:{width}"' if width else ""
    words = f" {_e(explanation)}" if explanation else ""
    return (
        f'<figure{style}><a href="{_e(src)}"><img src="{_e(src)}" alt="{_e(caption)}"></a>'
        f"<figcaption><b>{_e(caption)}</b>{words}</figcaption></figure>"
    )


def _metric_table(rows: Sequence[MetricRow], css_id: str) -> str:
    """Rows of metrics as a table: label, value, unit, what it means."""
    out = [
        f'<table id="{_e(css_id)}" class="metrics">',
        "<tr><th>metric</th><th>value</th><th>unit</th><th>what it means</th></tr>",
    ]
    for r in rows:
        num = ' class="num"' if _is_number(r.text.split(" ± ")[0]) else ""
        out.append(
            f'<tr data-key="{_e(r.info.key)}"><th>{_e(r.info.label)}</th>'
            f"<td{num}>{_e(r.text)}</td><td>{_e(r.info.unit)}</td>"
            f'<td class="muted">{_e(r.info.explanation)}</td></tr>'
        )
    out.append("</table>")
    return "\n".join(out)


def _metrics_section(metrics: Mapping[str, Any]) -> list[str]:
    """The run's numbers by group (:mod:`slamkit.eval.glossary`), each named metric with its
    unit and explanation, the rest of its record under "more numbers"."""
    rows = list(metric_rows(metrics))
    out = ["<h2>Metrics</h2>", '<div id="metrics">']
    out.append(
        '<p class="muted">Angles in degrees, shares in per cent; <code>metrics.json</code> '
        "keeps radians and fractions.</p>"
    )
    for i, group in enumerate(GROUPS):
        named = [r for r in rows if r.info.group == group and r.named]
        more = [r for r in rows if r.info.group == group and not r.named]
        if not named and not more:
            continue
        slug = f"metrics-{i}"
        out.append(f'<section class="metric-group" id="{slug}"><h3>{_e(group)}</h3>')
        if named:
            out.append(_metric_table(named, f"{slug}-table"))
        if more:
            out.append(f"<details><summary>{len(more)} more numbers</summary>")
            out.append(_metric_table(more, f"{slug}-more"))
            out.append("</details>")
        out.append("</section>")
    out.append("</div>")
    return out


def _timing_rows(page: RunPage) -> list[tuple[str, str]]:
    rows = [(k, f"{v:.3f}") for k, v in page.timings.items()]
    runtime = page.metrics.get("runtime")
    if isinstance(runtime, Mapping):
        steps = page.metrics.get("steps")
        if "total_seconds" in runtime:
            rows.append(("estimator, all steps", f"{float(runtime['total_seconds']):.3f}"))
        if "mean_step_seconds" in runtime:
            rows.append(("estimator, mean step", f"{float(runtime['mean_step_seconds']):.6f}"))
        if "max_step_seconds" in runtime:
            rows.append(("estimator, largest step", f"{float(runtime['max_step_seconds']):.6f}"))
        if steps is not None:
            rows.append(("steps", str(steps)))
    return rows


def _warning_item(warning: Any) -> str:
    """One warning as a list item: a record's ``message`` (its ``kind`` as the tooltip), or
    the text as it is."""
    if isinstance(warning, Mapping):
        kind = warning.get("kind")
        title = f' title="{_e(kind)}"' if kind else ""
        return f"<li{title}>{_e(warning.get('message', json.dumps(warning)))}</li>"
    return f"<li>{_e(warning)}</li>"


def _reading_section(reading: ReadingSummary) -> list[str]:
    """ "Reading the data": the lines the run printed, then the records dropped and repaired
    by reason, the notes, and what the two words mean."""
    out = ["<h2>Reading the data</h2>"]
    out.append('<p id="reading">' + "<br>".join(_e(line.strip()) for line in reading.lines()))
    out[-1] += "</p>"
    if reading.clean:
        out.append(f'<p class="muted">every one of the {_e(reading.what)} read as it was</p>')
        return out
    rows = [
        (verb, reason, str(n))
        for verb, counts in (("dropped", reading.dropped), ("repaired", reading.repaired))
        for reason, n in counts.items()
    ]
    if rows:
        out.append(_table(("", "reason", reading.what), rows, "reading-counts"))
    if reading.notes:
        out.append("<p>notes on the whole file:</p>")
        items = "".join(f"<li>{_e(n)}</li>" for n in reading.notes)
        out.append(f'<ul id="reading-notes">{items}</ul>')
    out.append(
        f'<p class="muted">Repaired: kept, after a fix the reason names (a stamp re-made, '
        f"a geometry read from the beam increment). Dropped: left out, the reader could not "
        f"use it; more than {MAX_DROPPED_SHARE:.0%} of a file's {_e(reading.what)} (and more "
        f"than {FEW_DROPPED}) dropped is an error, never a result.</p>"
    )
    return out


def run_html(page: RunPage) -> str:
    """The HTML of one run's page (figures linked relative to the run folder)."""
    body = [f"<h1>{_e(page.title)}</h1>"]
    seed = page.metrics.get("seed", page.config.get("seed"))
    preset = page.config.get("preset")
    facts = [("estimator", page.estimator), ("data set", page.dataset)]
    if seed is not None:
        facts.append(("seed", str(seed)))
    if preset:
        facts.append(("preset", str(preset)))
    shown = {r.info.key: r for r in metric_rows(page.metrics)}
    facts += [(shown[k].info.heading, shown[k].text) for k in HEADLINE if k in shown]
    body.append(_table(None, facts, "summary"))
    judged = page.metrics.get("verdict")
    if isinstance(judged, dict) and "line" in judged:  # (older metrics.json have none)
        state = "consistent" if judged.get("consistent") else "doubtful"
        body.append(f'<p id="verdict" class="{state}"><b>Verdict:</b> {_e(judged["line"])}</p>')
    warnings = page.metrics.get("warnings") or []
    if warnings:  # the consistency monitor's and the estimator's findings
        body.append("<h2>Warnings</h2>")
        body.append('<ul id="warnings">' + "".join(_warning_item(w) for w in warnings) + "</ul>")
    body.append("<h2>Estimator</h2>")
    body.append(f"<p>{_e(page.estimator_description or page.estimator)}</p>")
    body.append("<h2>Data set</h2>")
    body.append(f"<p>{_e(page.dataset_description or page.dataset)}</p>")
    if page.reading is not None:
        body.extend(_reading_section(page.reading))
    body.append("<h2>Figures</h2>")
    if page.figures:
        body.extend(_figure(n, n, explanation=FIGURE_CAPTIONS.get(n, "")) for n in page.figures)
    else:
        body.append('<p class="muted">no figures (run without --no-plots to get them)</p>')
    body.extend(_metrics_section(page.metrics))
    counts = page.metrics.get("diagnostics")
    if isinstance(counts, Mapping) and counts:
        body.append("<h2>The estimator's own counts (all)</h2>")
        body.append(
            '<p class="muted">What the estimator counted of itself (keyframes, matches, '
            "closures tried and refused by reason, particles, landmarks, …), as in "
            "<code>metrics.json</code>'s <code>diagnostics</code>; the signals read from "
            "them are in the metrics above. Angles here are in radians.</p>"
        )
        rows = [(_in_words(k), v) for k, v in flatten_metrics(counts).items()]
        body.append(_table(("count", "value"), rows, "diagnostics"))
    body.append("<h2>Timings [s]</h2>")
    body.append(_table(("phase", "seconds"), _timing_rows(page), "timings"))
    body.append("<h2>Configuration (config.json)</h2>")
    body.append(f"<pre>{_e(json.dumps(page.config, indent=2))}</pre>")
    body.append("<h2>Files</h2>")
    links = ", ".join(f'<a href="{_e(n)}">{_e(n)}</a>' for n in page.files)
    body.append(f"<p>{links}</p>")
    return _page(page.title, body)


def _relative(target: Path, start: Path) -> str:
    """``target`` as a URL path relative to the folder ``start`` (absolute when the two are
    on different drives)."""
    try:
        rel = os.path.relpath(target.resolve(), start.resolve())
    except ValueError:  # pragma: no cover - Windows, different drives
        return target.resolve().as_uri()
    return Path(rel).as_posix()


def compare_html(pages: Sequence[RunPage], out_dir: str | os.PathLike[str]) -> str:
    """The HTML of a page comparing ``pages`` side by side, to be written into ``out_dir``
    (figures linked relative to it): the runs, one metrics table with a column per run,
    and each kind of figure in a row across the runs."""
    if not pages:
        raise InputError("compare: expected at least one run folder")
    where = Path(out_dir)
    labels = [f"{i + 1}: {p.title}" for i, p in enumerate(pages)]
    title = "slamkit: " + " vs ".join(p.title for p in pages)
    body = [f"<h1>{_e('Comparison of ' + str(len(pages)) + ' runs')}</h1>"]
    run_rows = []
    for label, p in zip(labels, pages, strict=True):
        report = p.folder / "report.html"
        link = _relative(report if report.is_file() else p.folder, where)
        run_rows.append(
            f'<tr><th>{_e(label)}</th><td><a href="{_e(link)}">{_e(p.folder)}</a></td>'
            f"<td>{_e(p.estimator_description)}</td><td>{_e(p.dataset_description)}</td></tr>"
        )
    body.append(
        '<table id="runs"><tr><th>run</th><th>folder</th><th>estimator</th>'
        "<th>data set</th></tr>" + "".join(run_rows) + "</table>"
    )
    flat = [flatten_metrics(p.metrics) for p in pages]
    keys: list[str] = []
    for f in flat:
        keys.extend(k for k in f if k not in keys)
    rows = [(k, *(f.get(k, "—") for f in flat)) for k in keys]
    body.append("<h2>Metrics</h2>")
    body.append(_table(("metric", *labels), rows, "metrics"))
    body.append("<h2>Figures</h2>")
    kinds: list[str] = []
    for p in pages:
        kinds.extend(n for n in p.figures if n not in kinds)
    kinds.sort(key=_figure_key)
    for kind in kinds:
        body.append(f"<h3>{_e(kind)}</h3>")
        cells = []
        for label, p in zip(labels, pages, strict=True):
            if kind in p.figures:
                cells.append(_figure(_relative(p.folder / kind, where), label))
            else:
                cells.append(f'<p class="muted">{_e(label)}: no {_e(kind)}</p>')
        body.append('<div class="runs">' + "".join(cells) + "</div>")
    return _page(title, body)


def _write_text(path: Path, text: str) -> Path:
    tmp = path.with_name(f".{path.name}.tmp")
    tmp.write_text(text, encoding="utf-8")
    os.replace(tmp, path)
    return path


def write_run_page(page: RunPage, name: str = "report.html") -> Path:
    """Write :func:`run_html` of ``page`` into its folder; returns the path."""
    return _write_text(page.folder / name, run_html(page))


def write_compare_page(
    pages: Sequence[RunPage], out_dir: str | os.PathLike[str], name: str = "compare.html"
) -> Path:
    """Write :func:`compare_html` of ``pages`` into ``out_dir`` (created); returns the path."""
    where = Path(out_dir)
    where.mkdir(parents=True, exist_ok=True)
    return _write_text(where / name, compare_html(pages, where))
