"""The gallery: a few example scenarios, run while the site is built (mkdocs-gen-files).

Each page is what one command wrote: ``formationlab run examples/NAME.toml --out DIR`` runs in
a temporary folder, and its page shows the command, the verdict it printed, numbers from its
``summary.json`` and its figures. A command that fails fails the build (``mkdocs build``
stops with its output), so the pages cannot show a stale result. Only examples that finish in
a few seconds are run; the commands run two at a time. ``FORMATIONLAB_GALLERY=off`` writes
the pages without running anything (for ``mkdocs serve`` while editing the other pages).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import mkdocs_gen_files

ROOT = Path(__file__).resolve().parents[2]

FIGURES = [
    ("trajectories.png", "Trajectories"),
    ("distance_errors.png", "Distance errors"),
    ("lyapunov.png", "Lyapunov function V"),
    ("controls_x.png", "Controls, x"),
    ("controls_y.png", "Controls, y"),
]


@dataclass(frozen=True, kw_only=True)
class Example:
    """One gallery page: the scenario it runs and the page of the docs that explains it."""

    name: str  # examples/<name>.toml
    title: str
    about: str  # Markdown: what to look at, with a link into the docs
    expect: str  # the outcome the docs claim; the build fails on any other


EXAMPLES = [
    Example(
        name="paper-simulation-1",
        title="The paper's simulation 1",
        about="The restrictions stay off and the distance term forms the counter-clockwise "
        "triangle; V decreases monotonically (the paper's figs. 4-7, "
        "[the paper, equation by equation](../paper.md)).",
        expect="desired",
    ),
    Example(
        name="paper-simulation-2",
        title="The paper's simulation 2, exact symmetric start",
        about="The run never leaves the mirror-symmetric subspace and stops at a shrunken, "
        "wrongly oriented triangle: a stable equilibrium of the paper's law "
        "([undesired equilibria](../equilibria.md)).",
        expect="incorrect",
    ),
    Example(
        name="square-with-diagonals",
        title="Square with both diagonals",
        about="Four robots on the complete graph reach the square with the template's "
        "orientation; from random starts the distance law ends in a wrong shape 42 % of the "
        "time ([Monte-Carlo studies](../studies.md)).",
        expect="desired",
    ),
    Example(
        name="hexagon",
        title="Hexagon on a minimally rigid graph",
        about="Six robots on 9 edges reach the regular hexagon from this start; from random "
        "starts a quarter of the runs never stop ([formations that never stop](../drifting.md)).",
        expect="desired",
    ),
    Example(
        name="paper-simulation-2-unicycle-near-identity",
        title="Simulation 2 on unicycles",
        about="The paper's law on unicycles through the near-identity transform "
        "([robot models](../robot-models.md)).",
        expect="desired",
    ),
]


@dataclass(frozen=True, kw_only=True)
class Ran:
    """What one command printed and wrote."""

    example: Example
    command: str
    verdict: str
    summary: dict
    figures: dict[str, bytes]
    seconds: float


def run(example: Example, scratch: Path) -> Ran:
    """Run ``formationlab run`` on the example; raise with its output if it fails."""
    out = scratch / example.name
    args = ["run", f"examples/{example.name}.toml", "--out"]
    start = time.perf_counter()
    proc = subprocess.run(
        [sys.executable, "-m", "formationlab", *args, str(out)],
        cwd=ROOT,
        capture_output=True,
        text=True,
        env={**os.environ, "COLUMNS": "100"},
        check=False,
    )
    seconds = time.perf_counter() - start
    command = "formationlab " + " ".join([*args, "DIR"])
    if proc.returncode != 0:
        raise RuntimeError(
            f"gallery: `{command}` exited with status {proc.returncode}:\n"
            f"{proc.stdout}{proc.stderr}"
        )
    summary = json.loads((out / "summary.json").read_text())
    if summary["outcome"] != example.expect:
        raise RuntimeError(
            f"gallery: `{command}` ended {summary['outcome']!r}, the docs say {example.expect!r}"
        )
    verdict = proc.stdout.replace(f"{out}/", "DIR/").replace(str(out), "DIR").strip()
    figures = {name: (out / name).read_bytes() for name, _ in FIGURES if (out / name).exists()}
    if not figures:
        raise RuntimeError(f"gallery: `{command}` wrote no figure")
    return Ran(
        example=example,
        command=command,
        verdict=verdict,
        summary=summary,
        figures=figures,
        seconds=seconds,
    )


def _number(value: object, unit: str = "") -> str:
    if value is None:
        return "—"
    if isinstance(value, float):
        return f"{value:.3g}{unit}"
    return f"{value}{unit}"


def page(ran: Ran) -> str:
    """The Markdown of one example's page."""
    ex, s = ran.example, ran.summary
    scenario = (ROOT / "examples" / f"{ex.name}.toml").read_text()
    rows = [
        ("outcome", f"`{s['outcome']}`"),
        ("status", f"`{s['status']}`"),
        ("orientation", _number(s.get("orientation"))),
        ("robots, edges", f"{s['n_robots']}, {s['n_edges']}"),
        ("converged at", _number(s.get("converged_time"), " s")),
        ("ran to", _number(s.get("final_time"), " s")),
        ("max distance error", _number(s.get("max_distance_error"), " m")),
    ]
    lines = [
        f"# {ex.title}",
        "",
        ex.about,
        "",
        f"This page was made while the site was built, by this command "
        f"(formationlab {s.get('formationlab_version', '?')}, {ran.seconds:.1f} s):",
        "",
        "```bash",
        ran.command,
        "```",
        "",
        "It printed:",
        "",
        "``` { .text .wrap }",
        ran.verdict,
        "```",
        "",
        "From `DIR/summary.json`:",
        "",
        "| quantity | value |",
        "| --- | --- |",
        *(f"| {k} | {v} |" for k, v in rows),
        "",
    ]
    for name, title in FIGURES:
        if name in ran.figures:
            lines += [f"## {title}", "", f"![{title}: {ex.name}]({ex.name}/{name})", ""]
    lines += [
        f"## The scenario file, `examples/{ex.name}.toml`",
        "",
        "```toml",
        scenario.rstrip(),
        "```",
        "",
    ]
    return "\n".join(lines)


def index(runs: list[Ran], seconds: float) -> str:
    """The Markdown of the gallery's first page."""
    lines = [
        "# Gallery",
        "",
        "Example scenarios from `examples/`, run while this site was built: each page shows "
        "the command, the verdict it printed, its `summary.json` and its figures. "
        "A command that fails, or ends in another outcome than the documentation says, "
        "fails the build. Run any of them yourself with "
        "`formationlab run examples/NAME.toml --out runs/NAME` (add `--animate` for an "
        "animation); more examples are listed in [scenario files](../scenarios.md).",
        "",
        "| example | outcome | converged at | ran to | command time |",
        "| --- | --- | --- | --- | --- |",
    ]
    for ran in runs:
        s = ran.summary
        lines.append(
            f"| [{ran.example.title}]({ran.example.name}.md) | `{s['outcome']}` | "
            f"{_number(s.get('converged_time'), ' s')} | {_number(s.get('final_time'), ' s')} | "
            f"{ran.seconds:.1f} s |"
        )
    lines += [
        "",
        f"The {len(runs)} commands took {seconds:.1f} s of wall time in all (two at a time).",
        "",
    ]
    return "\n".join(lines)


def skipped() -> None:
    """Placeholder pages, for ``FORMATIONLAB_GALLERY=off mkdocs serve`` while writing."""
    note = (
        "The gallery was not run in this build (`FORMATIONLAB_GALLERY=off`); "
        "`mkdocs build` without it runs the examples.\n"
    )
    with mkdocs_gen_files.open("gallery/index.md", "w") as f:
        f.write(f"# Gallery\n\n{note}")
    for ex in EXAMPLES:
        with mkdocs_gen_files.open(f"gallery/{ex.name}.md", "w") as f:
            f.write(f"# {ex.title}\n\n{ex.about}\n\n{note}")


def main() -> None:
    if os.environ.get("FORMATIONLAB_GALLERY") == "off":
        skipped()
        return
    start = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="formationlab-gallery-") as scratch:
        with ThreadPoolExecutor(max_workers=2) as pool:
            runs = list(pool.map(lambda ex: run(ex, Path(scratch)), EXAMPLES))
    seconds = time.perf_counter() - start
    for ran in runs:
        with mkdocs_gen_files.open(f"gallery/{ran.example.name}.md", "w") as f:
            f.write(page(ran))
        for name, data in ran.figures.items():
            with mkdocs_gen_files.open(f"gallery/{ran.example.name}/{name}", "wb") as f:
                f.write(data)
    with mkdocs_gen_files.open("gallery/index.md", "w") as f:
        f.write(index(runs, seconds))


main()
