"""``lanro play``: a person gives a trained agent its instructions, and corrects it while it acts."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Annotated, Any

import typer
from rich.console import Console

from lanrocli.cli.arguments import device_option, env_changes, fail, with_env_options
from lanrocli.envs.settings import CORRECTION_LIMIT
from lanrocli.tasks import Task


@with_env_options(
    max_episode_steps=f"Steps per episode (default: {CORRECTION_LIMIT}, as for a correction episode: any episode "
    "may be corrected)."
)
def play_command(
    checkpoint: Annotated[
        Path,
        typer.Argument(
            metavar="CHECKPOINT",
            help="A checkpoint directory, a pointer such as RUN/stage-1-single/best, or a run folder (its latest).",
        ),
    ],
    task: Annotated[
        Task | None, typer.Option(help="Task (default: the checkpoint's; another needs the same actions).")
    ] = None,
    seed: Annotated[int, typer.Option(min=0, help="Episode i draws its scene with seed SEED + i - 1.")] = 0,
    episodes: Annotated[
        int | None, typer.Option(min=1, help="Stop after this many episodes (default: when the input ends).")
    ] = None,
    steps_per_line: Annotated[
        int, typer.Option(min=1, help="Steps the agent acts before each further line is read.")
    ] = 10,
    device: Annotated[
        str | None, typer.Option(callback=device_option, help="cpu, cuda or cuda:N (default: cuda if available).")
    ] = None,
    gif: Annotated[
        Path | None,
        typer.Option(help="Folder for one GIF per episode (episode-1.gif, ...), captioned with the sentence."),
    ] = None,
    gui: Annotated[
        bool, typer.Option("--gui", help="Show the episodes in PyBullet's window (needs a display).")
    ] = False,
    **env_options: Any,
) -> None:
    """Give a trained agent instructions yourself, and correct it while it acts.

    Each episode draws a scene from the checkpoint's stage (options change it) and shows its objects; the next line
    is the instruction. The agent then acts --steps-per-line steps before each further line: text is a correction,
    appended to the instruction as the instructor does (a later one replaces it), and an empty line lets it go on.
    An episode lasts --max-episode-steps steps and ends sooner when the task holds for the object the sentence
    singles out; the next line is the next episode's instruction. Unknown words are named and read as <unk>;
    a sentence outside the grammar is flagged and read all the same.

    Lines come from standard input, so a script can be piped in, for example:
    printf 'push the red cube\\nsorry the blue cube\\n' | lanro play RUN --gif out.
    When the input ends, the running episode goes on to its end and play stops.
    """
    from lanrocli.cli.play_session import PlayError, PlayOptions, play

    options = PlayOptions(task, env_changes(env_options), seed, episodes, steps_per_line, gif, gui, device)
    try:
        play(checkpoint, options, sys.stdin, Console(soft_wrap=True))
    except PlayError as error:
        raise fail(str(error)) from None
