"""``polar-sim reproduce``: every experiment, one report of the dissertation's findings.

The report (``report.md`` and ``report.html`` with the figures inlined) opens with where it came
from (polar_sim version and commit, packages, machine, wall time), then the findings table (for
each published figure or table we reproduce: the published claim, ours, a verdict), the status of
every experiment (checks met, recorded misses, failures, trial errors), and each run's summary.

A recorded miss (a target we miss and say so in ``benchmarks/RESULTS.md``) shows as *missed* and
does not fail the command; a failed check that is not a recorded miss, or a trial error, does.
"""

from __future__ import annotations

import base64
import html
import json
import re
import time
import traceback
from pathlib import Path

from polar_sim.fileio import write_text
from polar_sim.runner.findings import findings_table
from polar_sim.runner.registry import get_experiment, list_experiments
from polar_sim.runner.report import cell

__all__ = ["reproduce", "write_report", "markdown_to_html"]


def reproduce(out, *, quick=None, split=None, only=None, workers=1, backend="local", address=None,
              trial_timeout=None, progress=True, report_only=False):
    """Run every experiment (or ``only`` these) into ``out/<name>`` and write the report.

    ``quick``: the CI size (default the full size). ``split`` (``"dev"`` or ``"test"``) applies to
    the experiments that declare it; the others run their default split, which the report states.
    Returns ``({name: RunResult}, report_path)``. An experiment that raises is reported as an error
    and the others still run. Before anything runs, a folder ``out/<name>`` that holds a run of
    another size, split or protocol, and (with ``backend="ray"``) a cluster that does not answer,
    raise ``ValueError`` naming ``out`` (or ``address``): nothing is run or written, and a good
    report in ``out`` is never replaced by one of failures.

    ``report_only=True`` runs nothing: it reads the finished run folders ``out/<name>`` back
    (:func:`~polar_sim.runner.run.load_run`; their ``trials/`` are not needed) and writes the report
    from them, e.g. for runs made over several sessions or on several machines. The size is the
    folders' (``quick`` given must agree). A folder that is missing, unfinished, or of a size or
    split other than the rest's, raises ``ValueError`` naming ``out``, and nothing is written.
    """
    from polar_sim.runner.run import run_experiment

    root = Path(out)
    names = list(only) if only else list_experiments()
    for n in names:
        get_experiment(n)        # unknown names fail before anything runs
    if report_only:
        results, walls, size = _assemble(root, names, quick, split)
        report = write_report(results, root, walls=walls, wall_s=sum(walls.values()), quick=size == "quick",
                              assembled=True)
        return results, report
    size = "quick" if quick else "full"
    _refuse_other_runs(root, names, size, split)
    if backend == "ray":
        from polar_sim.runner.backends import ray_connect

        ray_connect(int(workers), address)
    t0 = time.time()
    results, errors, walls = {}, {}, {}
    for i, name in enumerate(names, start=1):
        sp = split if (split in get_experiment(name).splits) else None
        t = time.time()
        try:
            results[name] = run_experiment(name, size=size, split=sp, out=root / name, workers=workers,
                                           backend=backend, address=address, trial_timeout=trial_timeout,
                                           progress=progress, label=f"[{i}/{len(names)}] {name}")
        except Exception as exc:  # noqa: BLE001 - one broken experiment must not stop the report
            errors[name] = f"{type(exc).__name__}: {exc}"
            (root / name).mkdir(parents=True, exist_ok=True)
            (root / name / "error.txt").write_text(traceback.format_exc())
        walls[name] = time.time() - t
    report = write_report(results, root, errors=errors, walls=walls, wall_s=time.time() - t0, quick=size == "quick")
    if errors:
        # Errors become failed runs so that the exit code says so.
        from polar_sim.runner.experiment import Check
        from polar_sim.runner.run import RunResult

        for name, err in errors.items():
            results[name] = RunResult(root / name, [], [Check("experiment ran", False, err)], [{"error": err}])
    return results, report


def _refuse_other_runs(root, names, size, split):
    """``ValueError`` naming ``out`` if a folder ``root/<name>`` holds a run that this one would not
    resume (another size, split or protocol, or a corrupt config.json): checked for every
    experiment before any runs, so the report is not replaced by one of refused runs."""
    from polar_sim.runner.run import read_folder_config

    for name in names:
        exp = get_experiment(name)
        sp = exp.pick_split(split if split in exp.splits else None)
        read_folder_config(root / name, {"experiment": name, "size": size, "split": sp,
                                         "params": exp.resolve_params(size, sp)})


def _assemble(root, names, quick, split):
    """The finished runs ``root/<name>`` for ``--report-only``: ``({name: RunResult}, walls, size)``.
    Every named folder must be a finished run, all of one size (``quick``'s if given) and, where
    an experiment declares ``split``, of that split; otherwise ``ValueError`` naming ``out``."""
    from polar_sim.runner.run import load_run

    if not root.is_dir():
        raise ValueError(f"out: {str(root)!r} is not a folder (--report-only reads the finished run folders in it)")
    loaded, problems = {}, []
    for name in names:
        try:
            loaded[name] = load_run(root / name, name)
        except ValueError as exc:
            problems.append(f"{name}: {str(exc).removeprefix('out: ')}")
    nothing = "; no report was written"
    if problems:
        hint = f"; --only {' '.join(loaded)} assembles the ones it holds" if loaded else ""
        raise ValueError(f"out: {len(problems)} of {len(names)} experiments have no finished run in {str(root)!r} "
                         f"(first: {problems[0]}){hint}{nothing}")
    sizes = {}
    for name, r in loaded.items():
        sizes.setdefault(r.config.get("size"), []).append(name)
    if len(sizes) > 1:
        raise ValueError(f"out: {str(root)!r} mixes sizes (" + "; ".join(f"{s}: {', '.join(n)}" for s, n in sizes.items())
                         + f"){nothing}")
    (size,) = sizes
    if quick is not None and size != ("quick" if quick else "full"):
        raise ValueError(f"out: {str(root)!r} holds {size}-size runs, not {'quick' if quick else 'full'}-size ones "
                         f"({'drop' if quick else 'add'} --quick){nothing}")
    if split is not None:
        other = [(n, r.config.get("split")) for n, r in loaded.items()
                 if split in get_experiment(n).splits and r.config.get("split") != split]
        if other:
            raise ValueError(f"out: {other[0][0]} in {str(root)!r} holds the {other[0][1]} split, not {split}{nothing}")
    return loaded, {n: _run_wall(r.config, 0.0) for n, r in loaded.items()}, size


def _rel(p, root):
    p = Path(p)
    return p.relative_to(root) if p.is_relative_to(root) else p


def _run_wall(config, fallback):
    """Seconds over every invocation on a run folder (an interrupted one counts as unknown)."""
    hist = config.get("history") or []
    walls = [h.get("wall_s") for h in hist]
    return sum(w for w in walls if w is not None) if walls and any(w is not None for w in walls) else fallback


def _commits(config):
    from polar_sim.runner.run import run_commits

    def short(c):
        return "unknown" if not c else c[:12] + ("+dirty" if c.endswith("+dirty") else "")

    return ", ".join(short(c) for c in run_commits(config)) or "unknown"


def write_report(results, out_dir, *, errors=None, walls=None, wall_s=None, quick=False, assembled=False):
    """Write ``report.md`` and ``report.html`` for ``{name: RunResult}``; returns the .md path.

    ``assembled``: the runs were read back from their folders, not run by this invocation (the
    provenance then says so, and the wall time is the sum of the runs' own)."""
    from polar_sim.runner.provenance import provenance

    out_dir = Path(out_dir)
    errors, walls = errors or {}, walls or {}
    prov = provenance()
    pk = ", ".join(f"{k} {v}" for k, v in prov["packages"].items())
    m = prov["machine"]
    lines = ["# polar_sim: reproducing the dissertation's findings", "",
             ("**Size: quick** (the CI size: one or a few seeds and a reduced grid per experiment). These are "
              "not the full figures: those are in `docs/results/` and `benchmarks/RESULTS.md`; "
              "`polar-sim reproduce` without `--quick` runs the full size." if quick else
              "**Size: full** (every seed and grid point each experiment declares)."), "",
             "Figures come from simulated scenes unless the experiment says otherwise (the Intel Lab log is real; "
             "gazebo1 is a Gazebo simulation).", "",
             "## Provenance", "",
             f"- polar_sim {prov['polar_sim']}, commit {prov['git_commit'] or 'unknown (not run from a git checkout)'}",
             f"- Python {prov['python']}; {pk}",
             f"- machine: {m['platform']}, {m['cpu']}, {m['cpus']} CPUs, {m['memory_gib']} GiB, "
             f"load {m['load_average_1min']:.2f}" if m.get("load_average_1min") is not None else
             f"- machine: {m['platform']}, {m['cpu']}, {m['cpus']} CPUs, {m['memory_gib']} GiB",
             (f"- assembled {prov['started']} from finished run folders (`--report-only`): the runs' own commits "
              "are in the experiments table; wall time summed over their invocations"
              if assembled else f"- finished {prov['started']}")
             + (f", wall time {wall_s / 60:.1f} min" if wall_s is not None else ""),
             ""]
    findings = [(name, f) for name, r in results.items() for f in r.findings]
    lines += ["## Findings", "",
              "For each published result we reproduce: the published claim, our figure, and a verdict "
              "(held / partly held / not held / not tested the same way). Only a full-size run on the protocol's "
              "seeds gives a verdict: a smaller run, or cells that cannot separate the methods (every one at "
              "100 %, say), read *insufficient evidence*, with the sample n the figures rest on.", ""]
    if findings:
        lines += findings_table(findings, experiment_column=True)
    else:
        lines.append("(no experiment in this run states findings)")
    lines += ["", "## Experiments", "",
              "Wall time sums every invocation on the experiment's folder (a run resumed after an "
              "interruption keeps its finished trials); *trials from* names the commits that ran them.", "",
              "| experiment | split (seeds) | trials | met | missed (recorded) | slow (timing) | failed | trial errors "
              "| wall (s) | trials from | folder |",
              "|---|---|---|---|---|---|---|---|---|---|---|"]
    for name, r in results.items():
        st = [c.status for c in r.checks]
        seeds = r.config.get("seeds", [])
        sd = f"{seeds[0]}..{seeds[-1]}" if len(seeds) > 1 else (str(seeds[0]) if seeds else "")
        lines.append(f"| {name} | {r.config.get('split', '')} ({sd}) | {len(r.table)} | {st.count('pass')} | "
                     f"{st.count('missed')} | {st.count('slow')} | {st.count('FAIL')} | {len(r.failures)} | "
                     f"{_run_wall(r.config, walls.get(name, 0)):.0f} | {_commits(r.config)} | "
                     f"{_rel(r.out_dir, out_dir)} |")
    for name, err in errors.items():
        lines.append(f"| {name} | | | | | | | **error**: {cell(err)} | {walls.get(name, 0):.0f} | | {name} |")
    misses = [(n, c) for n, r in results.items() for c in r.checks if c.status != "pass"]
    if misses:
        lines += ["", "Not met (*missed*: recorded in `benchmarks/RESULTS.md`; *slow*: a CPU-time check not met on this "
                  "run's machine, whose speed varies; speed is judged by the benchmarks on quiet cores):", "",
                  "| experiment | check | status | figures |", "|---|---|---|---|"]
        lines += [f"| {n} | {cell(c.name)} | {'**FAIL**' if c.status == 'FAIL' else c.status} | {cell(c.detail)} |"
                  for n, c in misses]
    for name, r in results.items():
        text = (r.out_dir / "summary.md").read_text() if (r.out_dir / "summary.md").is_file() else ""
        text = re.sub(r"^(#+) ", r"#\1 ", text, flags=re.M)
        rel = _rel(r.out_dir, out_dir)
        text = re.sub(r"!\[([^\]]*)\]\((?!http)([^)]+)\)", lambda mm: f"![{mm[1]}]({rel}/{mm[2]})", text)
        lines += ["", text]
    md = "\n".join(lines) + "\n"
    path = out_dir / "report.md"
    write_text(path, md, "out")
    write_text(out_dir / "report.html", markdown_to_html(md, base=out_dir, title="polar_sim report"), "out")
    write_text(out_dir / "report.json", json.dumps(
        {"provenance": prov, "wall_s": wall_s, "errors": errors,
         "experiments": {n: {"checks": [dict(name=c.name, status=c.status, detail=c.detail) for c in r.checks],
                             "findings": [f.__dict__ for f in r.findings], "trials": len(r.table),
                             "trial_errors": len(r.failures), "split": r.config.get("split")}
                         for n, r in results.items()}}, indent=2, default=str), "out")
    return path


# -- a small Markdown-to-HTML converter for the report's own subset --------------------------------
def _inline(text, base):
    def img(m):
        src = Path(base) / m[2]
        if src.is_file() and src.suffix.lower() == ".png":
            data = base64.b64encode(src.read_bytes()).decode()
            return f'<img alt="{html.escape(m[1])}" src="data:image/png;base64,{data}" style="max-width:100%">'
        return f'<img alt="{html.escape(m[1])}" src="{html.escape(m[2])}">'

    out, pos = [], 0
    for m in re.finditer(r"!\[([^\]]*)\]\(([^)]+)\)", text):
        out.append(_fmt(text[pos:m.start()]))
        out.append(img(m))
        pos = m.end()
    out.append(_fmt(text[pos:]))
    return "".join(out)


def _fmt(text):
    t = html.escape(text, quote=False)
    t = re.sub(r"`([^`]+)`", r"<code>\1</code>", t)
    t = re.sub(r"\*\*([^*]+)\*\*", r"<strong>\1</strong>", t)
    t = re.sub(r"(?<![\w*])\*([^*\n]+)\*(?![\w*])", r"<em>\1</em>", t)
    t = re.sub(r"\[([^\]]+)\]\(([^)]+)\)", r'<a href="\2">\1</a>', t)
    return t.replace("\\|", "|")


def _cells(line):
    return [c.strip() for c in re.split(r"(?<!\\)\|", line.strip().strip("|"))]


def markdown_to_html(md, *, base=".", title="report"):
    """HTML of the Markdown subset our reports use (headings, paragraphs, lists, tables, images,
    code spans, bold, italics, links), with PNG images under ``base`` inlined as data URIs."""
    body, para, lines, i = [], [], md.splitlines(), 0

    def flush():
        if para:
            body.append(f"<p>{_inline(' '.join(para), base)}</p>")
            para.clear()

    while i < len(lines):
        line = lines[i]
        if line.startswith("|") and i + 1 < len(lines) and re.match(r"^\|(\s*:?-+:?\s*\|)+\s*$", lines[i + 1]):
            flush()
            head = "".join(f"<th>{_inline(c, base)}</th>" for c in _cells(line))
            rows, i = [], i + 2
            while i < len(lines) and lines[i].startswith("|"):
                rows.append("<tr>" + "".join(f"<td>{_inline(c, base)}</td>" for c in _cells(lines[i])) + "</tr>")
                i += 1
            body.append(f"<table><thead><tr>{head}</tr></thead><tbody>{''.join(rows)}</tbody></table>")
            continue
        m = re.match(r"^(#{1,6}) (.*)", line)
        if m:
            flush()
            body.append(f"<h{len(m[1])}>{_inline(m[2], base)}</h{len(m[1])}>")
        elif re.match(r"^\s*[-*] ", line):
            flush()
            items = []
            while i < len(lines) and re.match(r"^\s*[-*] ", lines[i]):
                item = re.sub(r"^\s*[-*] ", "", lines[i])
                items.append(f"<li>{_inline(item, base)}</li>")
                i += 1
            body.append(f"<ul>{''.join(items)}</ul>")
            continue
        elif not line.strip():
            flush()
        else:
            para.append(line)
        i += 1
    flush()
    style = ("body{font-family:sans-serif;max-width:1200px;margin:2em auto;line-height:1.4}"
             "table{border-collapse:collapse;margin:1em 0;font-size:90%}td,th{border:1px solid #bbb;padding:3px 6px}"
             "th{background:#eee}code{background:#f3f3f3;padding:0 3px}")
    return (f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>{html.escape(title)}</title>"
            f"<style>{style}</style></head><body>\n" + "\n".join(body) + "\n</body></html>\n")
