"""Score the baselines on the benchmark's protocols and write docs/benchmark.md's tables from their records.

Every (task, policy, protocol) record is kept as JSON under ``--records`` (one file per task and policy).
Only missing records (or those of an older protocol version) are scored, so the page can be filled in over
several sessions, and rebuilt from the records alone (``--render-only``); the tables go between the page's
markers. Policies: the scripted ``oracle``, ``mistaken`` and ``random``; ``shipped``, lanro's packaged agent
of the task; ``sb3``, every stable-baselines3 model trained by ``benchmarks/sb3_baseline.py`` under
``--sb3 DIR/TASK/seed=S``; ``lanro``, the final agent of every run under ``--runs DIR/TASK/seed=S``
(``lanro train TASK --seed S --out DIR/TASK/seed=S``).

    python benchmarks/benchmark_page.py --tasks push --policies oracle mistaken random shipped \\
        --protocols test correction_test paraphrase
    python benchmarks/benchmark_page.py --render-only
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import lanrocli
from lanrocli.evaluation.protocols import PROTOCOL_VERSION, PROTOCOLS
from lanrocli.evaluation.splits import with_interval
from lanrocli.tasks import TASKS

ROOT = Path(__file__).resolve().parent.parent
ORDER = {"lanro": 0, "oracle": 2, "mistaken": 3, "random": 4}
"""Rows in this order: lanro's agents, the other learners, then the scripted policies."""
SCRIPTED = ("oracle", "mistaken", "random")
COLUMNS: tuple[tuple[str, str, tuple[str, ...]], ...] = (
    ("test", "test: success", ()),
    ("correction_test", "correction test: corrected", ("corrected",)),
    ("correction_test", "after a negation", ("by_form", "negation")),
    ("paraphrase", "paraphrase: corrected", ("corrected",)),
    ("paraphrase", "same episodes, grammar", ("control", "corrected")),
    ("pairs", "pairs: success", ()),
    ("correction_words", "correction words: corrected", ("corrected",)),
    ("late_corrections", "late corrections: corrected", ("corrected",)),
    ("common_ground", "common ground: corrected", ("by_kind", "common_ground", "corrected")),
    ("blank_instruction", "blank sentence: success", ()),
    ("other_instruction", "another object's sentence: success on it", ()),
)
"""The page's columns: the protocol, the heading, where the rate sits in the record (none: its success)."""


def policies(task: str, names: list[str], sb3: Path | None, runs: Path | None) -> Iterator[tuple[str, Any]]:
    """(label, policy) of every policy asked for on ``task``; learners once per seed found."""
    from lanrocli.envs.policies import make_policy

    for name in names:
        if name in SCRIPTED:
            yield name, make_policy(name, task)
        elif name == "shipped":
            from lanrocli.pretrained import agent_path
            from lanrocli.train.trainer import load_policy

            yield "lanro, shipped agent", load_policy(agent_path(Path(task)))[1]
        elif name == "sb3" and sb3 is not None:
            from stable_baselines3 import SAC

            for folder in sorted((sb3 / task).glob("seed=*")):
                if (folder / "model.zip").is_file():
                    model = SAC.load(folder / "model.zip", device="cpu")
                    yield f"SB3 SAC, {folder.name}", model.policy  # the policy alone: no replay buffer to copy
        elif name == "lanro" and runs is not None:
            from lanrocli.train.trainer import load_policy

            for folder in sorted((runs / task).glob("seed=*")):
                yield f"lanro, {folder.name}", load_policy(folder)[1]


def records_file(records: Path, task: str, label: str) -> Path:
    return records / task / (label.replace(", ", "-").replace(" ", "_").replace("=", "") + ".json")


def score(args: argparse.Namespace) -> None:
    for task in args.tasks:
        for label, policy in policies(task, args.policies, args.sb3, args.runs):
            path = records_file(args.records, task, label)
            kept = json.loads(path.read_text()) if path.is_file() else {}
            for protocol in args.protocols:
                if protocol in kept and kept[protocol]["benchmark"]["version"] == PROTOCOL_VERSION:
                    continue
                start = time.perf_counter()
                record = lanrocli.evaluate(policy, task, protocol, workers=args.workers, label=label)
                record["benchmark"]["seconds"] = round(time.perf_counter() - start, 1)
                kept[protocol] = record
                path.parent.mkdir(parents=True, exist_ok=True)
                path.write_text(json.dumps(kept))
                print(f"{task} {label} {protocol}: {record['benchmark']['seconds']} s", flush=True)


def rate(record: dict[str, Any] | None, where: tuple[str, ...]) -> dict[str, Any] | None:
    node: Any = record
    for key in where:
        node = node.get(key) if isinstance(node, dict) else None
    if not where and record is not None:
        return {"episodes": record["episodes"], "success": record["success"], "ci": record["success_ci"]}
    return node if isinstance(node, dict) and "success" in node else None


def cell(found: list[dict[str, Any] | None]) -> str:
    """One policy's rate, or a learner's seeds: their mean and range, and the seeds counted."""
    rates = [r for r in found if r and r["episodes"]]
    if not rates:
        return "-"
    if len(found) == 1:
        return with_interval(rates[0])
    values = [100 * r["success"] for r in rates]
    seeds = f"{len(values)} seed" + ("s" if len(values) > 1 else "")
    return f"{statistics.mean(values):.1f} [{min(values):.1f}, {max(values):.1f}] ({seeds})"


BEGIN, END = "<!-- tables: written by benchmarks/benchmark_page.py -->", "<!-- end of tables -->"


def tables(records: Path) -> str:
    """The tables of every task's records, for the page between ``BEGIN`` and ``END``."""
    lines = [
        f"Protocol version {PROTOCOL_VERSION}. One policy: success in % [95% Wilson interval] (episodes counted). "
        "A learner's seeds: mean [lowest, highest] over its seeds. `-`: not scored yet."
    ]
    folders = {p.name: p for p in records.iterdir() if p.is_dir()} if records.is_dir() else {}
    for task_folder in [folders[task] for task in TASKS if task in folders]:
        by_label: dict[str, list[dict[str, Any]]] = {}
        for path in sorted(task_folder.glob("*.json")):
            kept = json.loads(path.read_text())
            if not kept:
                continue
            label = next(iter(kept.values()))["policy"]
            group = label.rsplit(", seed", 1)[0]
            by_label.setdefault(group, []).append(kept)
        lines += ["", f"## {task_folder.name}", "", "| policy | " + " | ".join(c[1] for c in COLUMNS) + " |"]
        lines.append("|---" * (len(COLUMNS) + 1) + "|")
        for group, kept in sorted(by_label.items(), key=lambda item: ORDER.get(item[0].split(",")[0], 1)):
            cells = [cell([rate(k.get(protocol), where) for k in kept]) for protocol, _, where in COLUMNS]
            lines.append(f"| {group} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def write_page(page: Path, records: Path) -> None:
    """Put the tables between the page's markers, leaving its own words as they are."""
    text = page.read_text()
    if BEGIN not in text or END not in text:
        raise SystemExit(f"{page} has no {BEGIN} ... {END} block to write the tables into")
    before, rest = text.split(BEGIN, 1)
    after = rest.split(END, 1)[1]
    page.write_text(f"{before}{BEGIN}\n{tables(records)}\n{END}{after}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--tasks", nargs="+", default=["push", "reach", "grasp", "lift"])
    parser.add_argument("--policies", nargs="+", default=[*SCRIPTED, "shipped", "sb3", "lanro"])
    parser.add_argument("--protocols", nargs="+", default=list(PROTOCOLS), choices=list(PROTOCOLS))
    parser.add_argument("--sb3", type=Path, help="folder of sb3_baseline.py models: SB3/TASK/seed=S/model.zip")
    parser.add_argument("--runs", type=Path, help="folder of lanro runs: RUNS/TASK/seed=S")
    parser.add_argument("--workers", type=int, default=os.cpu_count() or 1)
    parser.add_argument("--records", type=Path, default=ROOT / "docs" / "benchmark")
    parser.add_argument("--out", type=Path, default=ROOT / "docs" / "benchmark.md")
    parser.add_argument("--render-only", action="store_true", help="write the page from the records alone")
    args = parser.parse_args()
    if not args.render_only:
        score(args)
    write_page(args.out, args.records)
    print(f"wrote {args.out}", file=sys.stderr)


if __name__ == "__main__":
    main()
