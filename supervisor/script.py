"""The supervisor's script language: one action per line.

::

    # fetch the orange ball (comments start with '#')
    localize green_box
    goto green_box distance=0.7
    localize orange_ball
    reach right orange_ball
    grasp right as ball          # 'as NAME' names what the action returns (here: the object held)
    turn 180
    put ball on=yellow_table

A line is ``ACTION ARG... [KEY=VALUE...] [as NAME]``. Arguments are words (object names use
underscores: ``orange_ball``) or numbers. ``reach`` and ``grasp`` may name no hand (``reach
orange_ball``, ``grasp as ball``; or ``either``): the supervisor then chooses it. ``$NAME`` or a
bare ``NAME`` bound by an earlier ``as`` refers to what that action returned. Parsing checks every
line against the action signatures before anything runs, and errors name the line and suggest the
closest action.
"""

from __future__ import annotations

import difflib
import math
import shlex
from dataclasses import dataclass, field
from pathlib import Path

from services.errors import InvalidRequestError


@dataclass(frozen=True)
class Signature:
    """An action's arguments: positional names, optional keyword names, and a one-line help."""

    positional: tuple[str, ...]
    keywords: tuple[str, ...] = ()
    optional_positional: int = 0  # how many trailing positionals may be omitted
    help: str = ""

    def usage(self, name: str) -> str:
        required = self.positional[: len(self.positional) - self.optional_positional]
        optional = self.positional[len(required) :]
        parts = [name, *required, *(f"[{p}]" for p in optional), *(f"[{k}=...]" for k in self.keywords)]
        return " ".join(parts)


# The actions of the supervisor (the ball-fetching experiment of the motion-autonomy paper).
ACTIONS: dict[str, Signature] = {
    "detect": Signature(("object",), help="is the object in view now (no head motion)"),
    "localize": Signature(("object",), help="find the object's 3D position, looking around if needed"),
    "goto": Signature(("target",), ("distance",), help="walk in front of a place/object or to 'x,y,yaw'"),
    "turn": Signature(("angle_deg",), help="turn in place (positive = left)"),
    "walk": Signature(
        ("forward_m", "left_m", "yaw_deg"),
        optional_positional=1,
        help="walk relative to the robot (forward, left [m], then facing yaw_deg more; -0.3 0 steps back)",
    ),
    "reach": Signature(("hand", "target"), help="reach a hand to an object or 'x,y,z', stepping if needed"),
    "grasp": Signature(("hand",), help="close the hand; returns the object held"),
    "open": Signature(("hand",), help="open the hand, releasing what it holds"),
    "put": Signature(("object",), ("on",), help="put the held object on a place"),
    "look_at": Signature(("object",), help="turn the head toward an object"),
    "stand_up": Signature(
        ("beside_m", "budget_s"),
        optional_positional=2,
        help="get out of the chair (contact planning), stand beside it (the waist beside_m [m] to the left; "
        "budget [s])",
    ),
}

HANDS = ("left", "right")
#: The hand of a ``reach`` or ``grasp`` whose line names none: the supervisor chooses it (a reach: the hand
#: whose approach is clear of the object's neighbours; a grasp: the hand that reached).
EITHER_HAND = "either"
#: The actions whose hand may be left out (``open`` names the hand to open: it has no way to choose one,
#: and ``reach right`` with its target forgotten stays an error, not a search for an object "right").
CHOOSES_HAND = ("reach", "grasp")
#: Arguments (positional or ``key=value``) that are numbers: checked when the script is read, not when
#: the action runs (after connecting, after the actions before it).
NUMBERS = ("angle_deg", "forward_m", "left_m", "yaw_deg", "beside_m", "budget_s", "distance")


@dataclass(frozen=True)
class Step:
    """One parsed line of a script."""

    line: int
    action: str
    args: tuple[str, ...]
    kwargs: dict[str, str] = field(default_factory=dict)
    bind: str | None = None  # the name given with 'as NAME'

    def text(self) -> str:
        words = [self.action, *self.args, *(f"{k}={v}" for k, v in self.kwargs.items())]
        if self.bind:
            words += ["as", self.bind]
        return " ".join(words)


def parse_line(text: str, line: int = 1) -> Step | None:
    """Parse one line; None for blank/comment lines; InvalidRequestError saying what is wrong."""
    try:
        words = shlex.split(text, comments=True)
    except ValueError as exc:
        raise InvalidRequestError(f"line {line}: {exc}") from None
    if not words:
        return None
    action, rest = words[0].lower(), words[1:]
    signature = ACTIONS.get(action)
    if signature is None:
        hint = difflib.get_close_matches(action, ACTIONS, n=1)
        suggestion = f"; did you mean '{hint[0]}'?" if hint else ""
        raise InvalidRequestError(
            f"line {line}: unknown action '{action}'{suggestion} Actions: {', '.join(ACTIONS)}"
        )
    bind = None
    if len(rest) >= 2 and rest[-2] == "as":
        bind = rest[-1]
        rest = rest[:-2]
    args: list[str] = []
    kwargs: dict[str, str] = {}
    for word in rest:
        if "=" in word:
            key, value = word.split("=", 1)
            if key not in signature.keywords:
                valid = ", ".join(signature.keywords) or "none"
                raise InvalidRequestError(f"line {line}: '{action}' has no option '{key}' (options: {valid})")
            kwargs[key] = value
        else:
            args.append(word.removeprefix("$"))
    required = len(signature.positional) - signature.optional_positional
    if action in CHOOSES_HAND and len(args) == required - 1 and not (args and args[0] in HANDS):
        args.insert(signature.positional.index("hand"), EITHER_HAND)  # no hand named: the supervisor's choice
    if not required <= len(args) <= len(signature.positional):
        raise InvalidRequestError(
            f"line {line}: '{action}' takes {signature.usage(action)}, got {len(args)} argument(s)"
        )
    if "hand" in signature.positional:
        hand = args[signature.positional.index("hand")]
        if hand not in (*HANDS, EITHER_HAND):
            raise InvalidRequestError(
                f"line {line}: hand '{hand}' is not one of {', '.join(HANDS)} "
                f"(or {EITHER_HAND}, or none named)"
            )
    for name, value in [*zip(signature.positional, args, strict=False), *kwargs.items()]:
        if name in NUMBERS and not _is_finite_number(value):
            raise InvalidRequestError(f"line {line}: '{action}' {name} '{value}' is not a number")
    return Step(line=line, action=action, args=tuple(args), kwargs=kwargs, bind=bind)


def _is_finite_number(text: str) -> bool:
    try:
        return math.isfinite(float(text))
    except ValueError:
        return False


def parse_script(text: str) -> list[Step]:
    """Parse a whole script; every error of every line is reported at once."""
    steps: list[Step] = []
    errors: list[str] = []
    for number, raw in enumerate(text.splitlines(), start=1):
        try:
            step = parse_line(raw, number)
        except InvalidRequestError as exc:
            errors.append(exc.message)
            continue
        if step is not None:
            steps.append(step)
    if errors:
        raise InvalidRequestError("; ".join(errors), {"errors": errors})
    if not steps:
        raise InvalidRequestError("the script has no action (only blank lines or comments)")
    return steps


def load_script(path: str | Path) -> list[Step]:
    try:
        text = Path(path).read_text()
    except FileNotFoundError:
        raise InvalidRequestError(f"script {path} does not exist") from None
    return parse_script(text)


def parse_point(text: str, n: int, what: str) -> tuple[float, ...] | None:
    """An action argument 'x,y,z' (``n`` comma-separated numbers) -> floats, or None if ``text`` is a
    name; InvalidRequestError naming ``what`` if it is neither."""
    if not any(c.isdigit() for c in text) or "," not in text:
        return None
    try:
        values = tuple(float(v) for v in text.split(","))
    except ValueError:
        raise InvalidRequestError(
            f"{what} {text!r}: expected {n} comma-separated numbers or an object name"
        ) from None
    if len(values) != n:
        raise InvalidRequestError(f"{what} {text!r}: expected {n} numbers, got {len(values)}")
    return values
