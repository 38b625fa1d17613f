"""The instructor's language: object properties, the grammar of instructions and corrections, the vocabulary.
The tasks' names and verbs are read from the task classes (``lanrocli.tasks``) and offered here beside the
words they join.

Pure Python and numpy: nothing here knows of physics or torch.
"""

from lanrocli.language.grammar import (
    BEGINNING_WORDS,
    NAMING_FORMS,
    Form,
    Phrase,
    Sentence,
    all_corrections,
    all_instructions,
    all_phrases,
    all_sentences,
    ambiguous_phrases,
    correction,
    correction_forms,
    extend,
    identifying_phrases,
    instruction,
    max_sentence_words,
    object_phrases,
    pick,
    sample_sentence,
    sentence_stats,
)
from lanrocli.language.properties import (
    COLOURS,
    RARE_COLOUR_WORDS,
    RARE_WORD_COLOURS,
    SHAPE_WORDS,
    SHAPES,
    ObjectProps,
)
from lanrocli.language.vocabulary import (
    PAD_ID,
    UNK_ID,
    SentenceTooLong,
    Vocabulary,
    agent_vocabulary,
    grammar_vocabulary,
)
from lanrocli.tasks import TASK_VERBS, TASKS, check_task

__all__ = [
    "BEGINNING_WORDS",
    "NAMING_FORMS",
    "COLOURS",
    "PAD_ID",
    "RARE_COLOUR_WORDS",
    "RARE_WORD_COLOURS",
    "SHAPES",
    "SHAPE_WORDS",
    "TASKS",
    "TASK_VERBS",
    "UNK_ID",
    "Form",
    "ObjectProps",
    "Phrase",
    "Sentence",
    "SentenceTooLong",
    "Vocabulary",
    "all_corrections",
    "all_instructions",
    "all_phrases",
    "all_sentences",
    "ambiguous_phrases",
    "check_task",
    "correction",
    "correction_forms",
    "extend",
    "agent_vocabulary",
    "grammar_vocabulary",
    "identifying_phrases",
    "instruction",
    "max_sentence_words",
    "object_phrases",
    "pick",
    "sample_sentence",
    "sentence_stats",
]
