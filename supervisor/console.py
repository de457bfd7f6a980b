"""The voice-like text console: plain commands mapped to supervisor actions.

"take the orange ball", "go to the yellow table", "put it on the table", "turn left",
"look at the green box", "open your hand", "stop", "help". Object phrases are resolved against the
known object names (the perception models): "the table" means the only known object that is a table.
A command that is not understood gets a message naming the closest command it knows.
"""

from __future__ import annotations

import difflib
import re
from collections.abc import Callable, Sequence
from dataclasses import dataclass

from services.errors import InvalidRequestError
from supervisor.script import Step

HELD = "held"  # the name the console binds to the object in the hand


@dataclass(frozen=True)
class Command:
    """What a console line means: steps to run, or a control word (``stop``, ``help``)."""

    text: str
    steps: tuple[Step, ...] = ()
    control: str = ""  # "stop" | "help" | "quit" | ""


@dataclass(frozen=True)
class _Pattern:
    example: str
    regex: re.Pattern[str]
    build: Callable[[re.Match[str], Sequence[str], str], tuple[Step, ...]]


def _object(phrase: str, known: Sequence[str]) -> str:
    """Resolve 'the orange ball' / 'the table' / 'it' to a known object name."""
    words = [w for w in re.split(r"[\s_]+", phrase.lower().strip()) if w not in ("the", "a", "an", "that")]
    name = "_".join(words)
    if name in known:
        return name
    matches = [k for k in known if k.split("_")[-1] == name or k.endswith("_" + name)]
    if len(matches) == 1:
        return matches[0]
    if len(matches) > 1:
        raise InvalidRequestError(f"'{phrase}' is ambiguous: {' or '.join(matches)}?")
    hint = difflib.get_close_matches(name, known, n=1)
    suggestion = f" Did you mean '{hint[0].replace('_', ' ')}'?" if hint else ""
    raise InvalidRequestError(
        f"I don't know '{phrase}'.{suggestion} Known objects: {', '.join(k.replace('_', ' ') for k in known)}"
    )


def _step(action: str, *args: str, bind: str | None = None, **kwargs: str) -> Step:
    return Step(line=0, action=action, args=args, kwargs=dict(kwargs), bind=bind)


def _take(m: re.Match[str], known: Sequence[str], hand: str) -> tuple[Step, ...]:
    obj = _object(m["obj"], known)
    return (_step("localize", obj), _step("reach", hand, obj), _step("grasp", hand, bind=HELD))


def _goto(m: re.Match[str], known: Sequence[str], hand: str) -> tuple[Step, ...]:
    obj = _object(m["obj"], known)
    return (_step("localize", obj), _step("goto", obj))


def _put(m: re.Match[str], known: Sequence[str], hand: str) -> tuple[Step, ...]:
    place = _object(m["place"], known)
    return (_step("localize", place), _step("put", HELD, on=place))


def _turn(m: re.Match[str], known: Sequence[str], hand: str) -> tuple[Step, ...]:
    direction = m["dir"]
    degrees = float(m["deg"]) if m["deg"] else (180.0 if direction == "around" else 90.0)
    sign = -1.0 if direction == "right" else 1.0
    return (_step("turn", f"{sign * degrees:g}"),)


def _look(m: re.Match[str], known: Sequence[str], hand: str) -> tuple[Step, ...]:
    return (_step("look_at", _object(m["obj"], known)),)


def _find(m: re.Match[str], known: Sequence[str], hand: str) -> tuple[Step, ...]:
    return (_step("localize", _object(m["obj"], known)),)


def _open(m: re.Match[str], known: Sequence[str], hand: str) -> tuple[Step, ...]:
    return (_step("open", hand),)


_PATTERNS = (
    _Pattern("take the orange ball", re.compile(r"^(?:take|grab|grasp|pick up|fetch) (?P<obj>.+)$"), _take),
    _Pattern("go to the yellow table", re.compile(r"^(?:go|walk|move) (?:to|towards?) (?P<obj>.+)$"), _goto),
    _Pattern("put it on the table", re.compile(r"^(?:put|place|drop) (?:it|that) on (?P<place>.+)$"), _put),
    _Pattern(
        "turn left",
        re.compile(r"^turn (?P<dir>left|right|around)(?: by)?(?: (?P<deg>\d+(?:\.\d+)?)(?: deg\w*)?)?$"),
        _turn,
    ),
    _Pattern("look at the green box", re.compile(r"^look at (?P<obj>.+)$"), _look),
    _Pattern("find the green box", re.compile(r"^(?:find|locate|where is) (?P<obj>.+)$"), _find),
    _Pattern("open your hand", re.compile(r"^(?:open(?: your| the)? hand|release(?: it)?|let go)$"), _open),
)
_CONTROLS = {"stop": "stop", "halt": "stop", "help": "help", "?": "help", "quit": "quit", "exit": "quit"}


def interpret(text: str, known_objects: Sequence[str], hand: str = "right") -> Command:
    """Map one console line to a :class:`Command`; InvalidRequestError with a suggestion otherwise."""
    line = re.sub(r"\s+", " ", text.strip().lower().rstrip(".!?") or text.strip().lower())
    line = re.sub(r"^(?:please )|(?: please)$", "", line)
    if line in _CONTROLS:
        return Command(text=text, control=_CONTROLS[line])
    for pattern in _PATTERNS:
        match = pattern.regex.match(line)
        if match:
            return Command(text=text, steps=pattern.build(match, known_objects, hand))
    examples = [p.example for p in _PATTERNS] + ["stop", "help"]
    hint = difflib.get_close_matches(line, examples, n=1, cutoff=0.3)
    suggestion = f" The closest I know: '{hint[0]}'." if hint else ""
    raise InvalidRequestError(f"I did not understand '{text.strip()}'.{suggestion} Say 'help' for the list.")


def help_text() -> str:
    lines = ["Commands:"] + [f"  {p.example}" for p in _PATTERNS]
    lines += ["  stop   (abort the running action)", "  help", "  quit"]
    return "\n".join(lines)
