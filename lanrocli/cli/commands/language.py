"""``lanro sample-instructions``: the sentences the instructor can speak, sampled or all of them."""

from __future__ import annotations

import json
import sys
from typing import Annotated

import numpy as np
import typer

from lanrocli.cli.display.commands import print_grammar_stats, print_sampled, write_sentences_json
from lanrocli.core.choices import Split
from lanrocli.language import all_sentences, grammar_vocabulary, sample_sentence, sentence_stats
from lanrocli.tasks import Task


def sample_instructions(
    task: Annotated[Task, typer.Option(help="Task whose verbs the instructor uses.")] = Task.REACH,
    n: Annotated[int, typer.Option("--n", min=1, help="How many sentences to sample.")] = 10,
    seed: Annotated[int, typer.Option(min=0, help="Random seed; the same seed gives the same sentences.")] = 0,
    corrections: Annotated[
        bool, typer.Option("--corrections", help="Append a correction to each instruction.")
    ] = False,
    negations: Annotated[
        bool, typer.Option("--negations", help="Allow the negation beginning ('not the ...').")
    ] = False,
    rare: Annotated[bool, typer.Option("--rare", help="Allow rare colour words in instructions.")] = False,
    enumerate_all: Annotated[
        bool, typer.Option("--all", help="Enumerate every sentence of the grammar instead of sampling.")
    ] = False,
    as_json: Annotated[bool, typer.Option("--json", help="Print a JSON array on stdout.")] = False,
    stats: Annotated[
        bool, typer.Option("--stats", help="Print counts (distinct sentences, vocabulary size, L, per form) only.")
    ] = False,
    split: Annotated[
        Split | None,
        typer.Option(
            help="What the instructor says in N episodes of a generalisation split (paraphrase: phrasings training "
            "never hears) of the task's curriculum, the arm acting on a wrong object first so that it corrects.",
        ),
    ] = None,
) -> None:
    """Show sentences the instructor can speak: sampled, or all of them."""
    if split is not None:
        if corrections or negations or rare or enumerate_all or stats:
            raise typer.BadParameter(
                "a split's episodes set their own sentences; leave out --corrections, --negations, --rare, --all "
                "and --stats",
                param_hint="--split",
            )
        _split_sentences(task, split, n, seed, as_json)
        return
    if negations and not corrections:
        raise typer.BadParameter("--negations only affects corrections; add --corrections", param_hint="--negations")
    if enumerate_all:
        sentences = all_sentences(task.value, corrections, negations, rare)
    else:
        rng = np.random.default_rng(seed)
        sentences = iter([sample_sentence(rng, task.value, corrections, negations, rare) for _ in range(n)])
    vocab = grammar_vocabulary()
    if stats:
        st = sentence_stats(sentences)
        if as_json:
            summary = {
                "task": task.value,
                "sentences": st.sentences,
                "distinct_sentences": st.distinct,
                "vocabulary_size": len(vocab),
                "max_length": vocab.max_length,
                "by_form": st.by_form,
                "by_beginning": st.by_beginning,
            }
            typer.echo(json.dumps(summary))
        else:
            print_grammar_stats(task.value, st, vocab)
    elif as_json:
        write_sentences_json(sentences, vocab, sys.stdout)
    elif enumerate_all:
        for s in sentences:
            typer.echo(s.text)
    else:
        print_sampled(sentences, vocab, f"{task.value}: {n} sampled sentences (seed {seed})")


def _split_sentences(task: Task, split: Split, n: int, seed: int, as_json: bool) -> None:
    """The last sentence of ``n`` episodes of ``split``, episode i reset with seed ``seed + i``, played by
    the scripted policy that first does the task on a wrong object."""
    from lanrocli.envs.policies import make_policy
    from lanrocli.evaluation.benchmark import protocol_env
    from lanrocli.evaluation.protocols import PROTOCOLS

    env = protocol_env(task.value, PROTOCOLS[split.value])()
    policy = make_policy("mistaken", task.value)
    spoken = []
    try:
        for episode in range(n):
            observation, info = env.reset(seed=seed + episode)
            policy.reset(seed=seed + episode)
            done = False
            while not done:
                observation, _, terminated, truncated, info = env.step(policy.act(observation, info))
                done = terminated or truncated
            correction = info["correction"]
            spoken.append({"text": info["instruction_text"], "phrasing": correction and correction["phrasing"]})
    finally:
        env.close()
    if as_json:
        typer.echo(json.dumps(spoken))
        return
    for sentence in spoken:
        phrasing = f"  [{sentence['phrasing']}]" if sentence["phrasing"] else ""
        typer.echo(f"{sentence['text']}{phrasing}")
