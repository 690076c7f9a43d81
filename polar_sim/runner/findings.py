"""Findings: a published claim, our figure, and a verdict that respects the sample it rests on.

An experiment's ``findings(table, ctx)`` judges its figures (:data:`VERDICTS`). The runner then
weighs that judgement (:func:`weigh`). A run below the full size is a smoke test of the pipeline,
not evidence: every verdict reads **insufficient evidence** with the sample, e.g. "insufficient
evidence at this size (n = 50 frames of 2 sequences; every variant at 100.0 %)". At the full size
*held*, *partly held* and *not held* stand only on the protocol's seeds, with the sample the
finding says it needs, and with cells that can separate the methods; otherwise they too read
insufficient evidence, with the reason. The verdict the figures indicated is kept in
``indicated`` (``findings.json``, ``report.json``), not shown.

:func:`findings_table` renders findings as a Markdown table whose long notes move below it as
numbered notes, so no row runs to hundreds of characters.
"""

from __future__ import annotations

import dataclasses

__all__ = ["Finding", "VERDICTS", "DECISIVE", "INSUFFICIENT", "weigh", "verdict_text", "findings_table"]

#: The verdicts a finding can carry. An experiment gives one of the first four; the runner may
#: replace a decisive one with :data:`INSUFFICIENT`.
VERDICTS = ("held", "partly held", "not held", "not tested the same way", "insufficient evidence")
#: The verdicts that claim evidence, and so need a sample that can give it.
DECISIVE = ("held", "partly held", "not held")
INSUFFICIENT = "insufficient evidence"


@dataclasses.dataclass(frozen=True)
class Finding:
    """One row of the dissertation-findings table that ``polar-sim reproduce`` writes.

    ``source``: where the published claim is (chapter, figure or table); ``claim``: the published
    claim or number; ``ours``: our figure, with units (:mod:`polar_sim.runner.report`'s
    ``length``, ``percent``, ``duration``); ``verdict``: one of :data:`VERDICTS`; ``note``: what
    differs from the published setting (say it when our experiment tests something else).

    What the verdict rests on, optional: ``n``, the sample size (default: the run's trials) and
    ``n_of``, what it counts (``"frames of 2 sequences"``); ``n_needed``, the ``n`` below which
    these figures cannot separate the methods; ``saturated``, a description when every compared
    cell sits at a floor or ceiling (``"every variant at 100.0 %"``), so no difference can show.
    ``evidence`` and ``indicated`` are set by the runner (:func:`weigh`).
    """

    source: str
    claim: str
    ours: str
    verdict: str
    note: str = ""
    n: int | None = None
    n_of: str = ""
    n_needed: int | None = None
    saturated: str = ""
    evidence: str = ""
    indicated: str = ""

    def __post_init__(self):
        if self.verdict not in VERDICTS:
            raise ValueError(f"verdict: {self.verdict!r} is not one of {', '.join(VERDICTS)}")
        for name in ("n", "n_needed"):
            v = getattr(self, name)
            if v is not None and (isinstance(v, bool) or not isinstance(v, int) or v < 0):
                raise TypeError(f"{name}: expected an integer >= 0 or None, got {v!r}")
        for name in ("source", "claim", "ours", "note", "n_of", "saturated", "evidence", "indicated"):
            if not isinstance(getattr(self, name), str):
                raise TypeError(f"{name}: expected a string, got {type(getattr(self, name)).__name__}")


def weigh(finding: Finding, *, size: str, n_trials: int, seeds: int | None = None,
          full_seeds: int | None = None) -> Finding:
    """``finding`` with its verdict weighed against its sample.

    Below the full size every verdict becomes :data:`INSUFFICIENT` ("not tested the same way"
    too: a smaller run does not test it). At the full size a decisive verdict (:data:`DECISIVE`)
    does when the run has fewer than the protocol's ``full_seeds`` seeds (``seeds``, e.g. a
    ``--set seed=...``), when ``n`` is below the finding's ``n_needed``, or when its cells are
    ``saturated``. ``n_trials``: the run's finished trials, the ``n`` of a finding that states
    none. Idempotent.
    """
    if finding.verdict == INSUFFICIENT or (size == "full" and finding.verdict not in DECISIVE):
        return finding
    n, of = (finding.n, finding.n_of) if finding.n is not None else (n_trials, "trial" if n_trials == 1 else "trials")
    if size != "full":
        head = "at this size"
    elif seeds is not None and full_seeds is not None and seeds < full_seeds:
        head = f"with {seeds} of the protocol's {full_seeds} seeds"
    else:
        head = ""
    short = finding.n_needed is not None and n < finding.n_needed
    if not (head or short or finding.saturated):
        return finding
    detail = [f"n = {n} {of}".strip()] + ([f"{finding.n_needed} needed"] if short else []) \
        + ([finding.saturated] if finding.saturated else [])
    evidence = f"{head} ({'; '.join(detail)})".strip()
    return dataclasses.replace(finding, verdict=INSUFFICIENT, evidence=evidence, indicated=finding.verdict)


def verdict_text(finding: Finding, bold: bool = True) -> str:
    """The verdict as a report shows it: ``**held**``, or ``**insufficient evidence** at this size
    (n = 50 frames)``."""
    v = f"**{finding.verdict}**" if bold else finding.verdict
    return f"{v} {finding.evidence}" if finding.evidence else v


def _cell(text) -> str:
    return str(text).replace("|", "\\|").replace("\n", " ")


def findings_table(findings, *, experiment_column=False) -> list:
    """Markdown lines: a table of ``findings`` (a list of :class:`Finding`, or of ``(experiment
    name, Finding)`` with ``experiment_column``), each note replaced by a reference ``[k]``, and
    the notes below it, one a line."""
    head = "| source | published | ours | verdict | note |" + (" experiment |" if experiment_column else "")
    lines = [head, "|---" * head.count(" |") + "|"]
    notes = []
    for item in findings:
        name, f = item if experiment_column else (None, item)
        ref = ""
        if f.note:
            notes.append(f.note)
            ref = f"[{len(notes)}]"
        lines.append(f"| {_cell(f.source)} | {_cell(f.claim)} | {_cell(f.ours)} | {_cell(verdict_text(f))} | {ref} |"
                     + (f" {name} |" if experiment_column else ""))
    if notes:
        lines += ["", "Notes:", ""] + [f"- [{k}] {_cell(text)}" for k, text in enumerate(notes, start=1)]
    return lines
