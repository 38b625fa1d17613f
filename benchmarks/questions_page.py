"""The question test's figures in docs/questions.md and its plot of the asking rate against ambiguity.

Each record is what ``lanro eval AGENT --question-test --json`` prints, kept in ``docs/questions/`` as
``<task>-<agent>.json``; this script scores any agent named with ``--score`` first, then writes the table
between the markers of docs/questions.md and the plot ``docs/questions-asking.png``.

    python benchmarks/questions_page.py --score push-shipped=push reach-shipped=reach
    python benchmarks/questions_page.py --score push-seed0=runs/ask/push-s0
    python benchmarks/questions_page.py            # the page and the plot from the records alone
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
RECORDS = ROOT / "docs" / "questions"
PAGE = ROOT / "docs" / "questions.md"
PLOT = ROOT / "docs" / "questions-asking.png"
BEGIN, END = "<!-- questions table: begin -->", "<!-- questions table: end -->"
KINDS = ("clear", "ambiguity", "common_ground", "instruction_correction")


def score(name: str, agent: str) -> None:
    """Run the question test of ``agent`` and keep its record as ``name``."""
    RECORDS.mkdir(parents=True, exist_ok=True)
    printed = subprocess.run(
        ["lanro", "eval", agent, "--question-test", "--json"], check=True, capture_output=True, text=True
    ).stdout
    (RECORDS / f"{name}.json").write_text(json.dumps(json.loads(printed), indent=1) + "\n")


def percent(rate: dict[str, Any]) -> str:
    low, high = rate["ci"]
    return f"{100 * rate['success']:.1f} [{100 * low:.1f}, {100 * high:.1f}]"


def count(figure: dict[str, Any]) -> str:
    low, high = figure["ci"]
    return f"{figure['per_episode']:.3f} [{low:.3f}, {high:.3f}]"


def table(records: dict[str, dict[str, Any]]) -> list[str]:
    lines = [
        "| agent | kind | episodes | asked, % | success, % | success, questions off | wrong-object actions / "
        "episode | questions off | fewer |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for name, record in records.items():
        for kind in KINDS:
            on, off = record["questions"].get(kind), record["questions_off"].get(kind)
            if on is None or off is None:
                continue
            before, after = off["wrong_objects"]["per_episode"], on["wrong_objects"]["per_episode"]
            fewer = f"{100 * (1 - after / before):.0f}%" if before else "-"
            lines.append(
                f"| {name} | {kind.replace('_', ' ')} | {on['episodes']} | {percent(on['asked'])} | "
                f"{percent(on['success'])} | {percent(off['success'])} | {count(on['wrong_objects'])} | "
                f"{count(off['wrong_objects'])} | {fewer} |"
            )
    lines += [
        "",
        "| agent | threshold | kept on the test's scenes (level) | success without a question | corrected, on / off |",
    ]
    lines.append("|---|---|---|---|---|")
    for name, record in records.items():
        calibration = record["calibration"]
        lines.append(
            f"| {name} | {calibration['threshold']:.2g} | {percent(record['coverage'])} "
            f"({100 * calibration['level']:.0f}) | {percent(record['acted_without_asking'])} | "
            f"{percent(record['corrected'])} / {percent(record['off']['corrected'])} |"
        )
    return lines


def plot(records: dict[str, dict[str, Any]]) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figure, axes = plt.subplots(figsize=(6.4, 4.0))
    width = 0.8 / max(1, len(records))
    for k, (name, record) in enumerate(records.items()):
        fits = sorted(record["asked_by_fits"], key=int)
        rates = [record["asked_by_fits"][f] for f in fits]
        x = [int(f) + (k - (len(records) - 1) / 2) * width for f in fits]
        y = [100 * r["success"] for r in rates]
        low = [100 * (r["success"] - r["ci"][0]) for r in rates]
        high = [100 * (r["ci"][1] - r["success"]) for r in rates]
        axes.bar(x, y, width, yerr=[low, high], capsize=3, label=name)
    axes.set_xticks([1, 2, 3])
    axes.set_xlabel("objects the instruction may mean (to a listener with the common words)")
    axes.set_ylabel("episodes with a question, % (95% CI)")
    axes.set_ylim(0, 105)
    axes.legend(fontsize="small")
    axes.set_title("Asking rate against ambiguity: question test, held-out episodes")
    figure.tight_layout()
    figure.savefig(PLOT, dpi=120)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--score", nargs="*", default=[], metavar="NAME=AGENT", help="agents to test first")
    args = parser.parse_args()
    for pair in args.score:
        name, _, agent = pair.partition("=")
        if not agent:
            sys.exit(f"--score takes NAME=AGENT, got {pair!r}")
        score(name, agent)
    records = {path.stem: json.loads(path.read_text()) for path in sorted(RECORDS.glob("*.json"))}
    if not records:
        sys.exit(f"no records in {RECORDS}: score an agent with --score NAME=AGENT")
    page = PAGE.read_text()
    start, stop = page.index(BEGIN) + len(BEGIN), page.index(END)
    PAGE.write_text(page[:start] + "\n" + "\n".join(table(records)) + "\n" + page[stop:])
    plot(records)
    print(f"wrote {PAGE.relative_to(ROOT)} and {PLOT.relative_to(ROOT)} from {len(records)} records")


if __name__ == "__main__":
    main()
