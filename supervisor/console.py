"""The voice-like text console: what people say, mapped to supervisor actions.

The understanding itself is :mod:`supervisor.language` (a small grammar: synonyms, filler, objects by
colour and kind, "it", compound commands, relative motions, numbers and units, questions when a
phrase is ambiguous). This module is what the console loop (:mod:`supervisor.repl`) and
``humanoid console --explain`` use: a :class:`~supervisor.language.Listener` per session,
:func:`interpret` for one line without a conversation, :func:`help_text`, :func:`explain`.
"""

from __future__ import annotations

from collections.abc import Sequence

from services.errors import InvalidRequestError
from supervisor.language import CAN_DO, HELD, Listener, Understanding
from supervisor.script import EITHER_HAND

__all__ = ["HELD", "Command", "Listener", "explain", "help_text", "interpret"]

#: What one console line means (steps, a control word, or something to say).
Command = Understanding

EXAMPLES = (
    "take the orange ball",
    "could you bring the orange ball to the yellow table, please",
    "grab the orange ball and put it on the table",
    "go to the green box, then turn around",
    "step back / take two steps to the left / move forward half a metre",
    "turn 45 degrees to the right / turn a bit to the left",
    "look at the green box / can you see the orange ball?",
    "let go / open your hand",
)


def interpret(text: str, known_objects: Sequence[str], hand: str = EITHER_HAND) -> Understanding:
    """One line on its own (no conversation): InvalidRequestError for a refusal or a question."""
    understanding = Listener(known_objects, hand).hear(text)
    if understanding.refused or understanding.control == "ask":
        raise InvalidRequestError(understanding.say)
    return understanding


def explain(lines: Sequence[str], known_objects: Sequence[str], hand: str = EITHER_HAND) -> str:
    """What each line would run, in one conversation (a question is answered by the next line)."""
    listener = Listener(known_objects, hand)
    return "\n".join(listener.hear(line).explain() for line in lines)


def help_text() -> str:
    lines = ["Commands: say what to do, in your own words; for example:"] + [f"  {e}" for e in EXAMPLES]
    lines += [
        CAN_DO + ".",
        "  stop   (abort the running action)",
        "  help",
        "  quit",
        "Several commands in one line: join them with 'and', 'then' or commas.",
    ]
    return "\n".join(lines)
