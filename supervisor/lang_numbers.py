"""Numbers and quantities as people say them: "two", "twenty five", "one and a half", "half a metre",
"50 cm", "a quarter turn", "a bit". Used by :mod:`supervisor.language`; no bus, no state.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

_UNITS_WORDS = {
    "zero": 0,
    "one": 1,
    "two": 2,
    "three": 3,
    "four": 4,
    "five": 5,
    "six": 6,
    "seven": 7,
    "eight": 8,
    "nine": 9,
    "ten": 10,
    "eleven": 11,
    "twelve": 12,
    "thirteen": 13,
    "fourteen": 14,
    "fifteen": 15,
    "sixteen": 16,
    "seventeen": 17,
    "eighteen": 18,
    "nineteen": 19,
}
_TENS_WORDS = {
    "twenty": 20,
    "thirty": 30,
    "forty": 40,
    "fifty": 50,
    "sixty": 60,
    "seventy": 70,
    "eighty": 80,
    "ninety": 90,
}
_FRACTIONS = {"half": 0.5, "quarter": 0.25, "third": 1 / 3}

#: A length unit -> metres.
LENGTH_UNITS = {
    "m": 1.0,
    "meter": 1.0,
    "meters": 1.0,
    "metre": 1.0,
    "metres": 1.0,
    "cm": 0.01,
    "centimeter": 0.01,
    "centimeters": 0.01,
    "centimetre": 0.01,
    "centimetres": 0.01,
    "mm": 0.001,
    "millimeter": 0.001,
    "millimeters": 0.001,
    "millimetre": 0.001,
    "millimetres": 0.001,
    "ft": 0.3048,
    "foot": 0.3048,
    "feet": 0.3048,
    "in": 0.0254,
    "inch": 0.0254,
    "inches": 0.0254,
}
#: An angle unit -> degrees.
ANGLE_UNITS = {
    "deg": 1.0,
    "degree": 1.0,
    "degrees": 1.0,
    "°": 1.0,
    "rad": 57.29577951308232,
    "radian": 57.29577951308232,
    "radians": 57.29577951308232,
}
#: Turns as fractions of a full turn -> degrees.
TURN_WORDS = {"quarter": 90.0, "half": 180.0, "full": 360.0, "whole": 360.0, "complete": 360.0}
#: One step of a relative walk [m] (a comfortable HRP-2 stride).
STEP_M = 0.2
#: "a few", "several" (steps, degrees, centimetres): about three.
FEW = 3
#: "twice", "thrice": a motion repeated (a step, or a turn of the default angle).
_REPEATS = {"twice": 2, "thrice": 3}
#: "a bit", "a little": a small walk [m] and a small turn [deg].
SMALL_M = 0.1
SMALL_DEG = 15.0

_NUMBER = r"\d+(?:\.\d+)?"


def words_to_digits(text: str) -> str:
    """Replace number words by digits: "twenty five" -> "25", "one and a half" -> "1.5",
    "half a" -> "0.5", "a couple of" -> "2". Other words are kept as they are."""
    words = text.split()
    out: list[str] = []
    i = 0
    while i < len(words):
        if words[i] in _REPEATS:  # "twice": "2 times"
            out += [f"{_REPEATS[words[i]]}", "times"]
            i += 1
            continue
        if words[i] == "one" and not _counts(words, i):
            out.append("one")  # "the blue one", "that one": a pronoun, not a number
            i += 1
            continue
        value, used = _read_number(words, i)
        if used:
            out.append(f"{value:g}")
            i += used
        else:
            out.append(words[i])
            i += 1
    return " ".join(out)


_COUNTED = {
    "step",
    "steps",
    "pace",
    "paces",
    "more",
    "and",
    "hundred",
    "quarter",
    "half",
    "full",
    "time",
    *LENGTH_UNITS,
    *ANGLE_UNITS,
}


def _counts(words: list[str], i: int) -> bool:
    """Whether ``one`` at ``words[i]`` is a number: followed by a unit or "and a half", or after "by"."""
    nxt = words[i + 1] if i + 1 < len(words) else ""
    prev = words[i - 1] if i > 0 else ""
    return nxt in _COUNTED or prev in ("by", "about", "around", "turn", "rotate", "move", "walk", "step")


def _read_number(words: list[str], i: int) -> tuple[float, int]:
    """The number spelled at ``words[i:]`` and how many words it takes (0: none)."""
    w = words[i]
    nxt = words[i + 1] if i + 1 < len(words) else ""
    if w in ("half", "a") and nxt == "half":  # "a half"
        return 0.5, 2
    if w == "half" and nxt in ("a", "an"):  # "half a metre"
        return 0.5, 2
    if w in ("a", "an") and nxt == "couple" and i + 2 < len(words) and words[i + 2] == "of":
        return 2, 3
    if w == "couple" and nxt == "of":
        return 2, 2
    if w == "dozen":
        return 12, 1
    if (w in ("a", "an") and nxt == "few") or w == "several":  # "a few steps": about three
        return FEW, 2 if w != "several" else 1
    total = 0.0
    used = 0
    if w in _TENS_WORDS or w in _UNITS_WORDS or re.fullmatch(_NUMBER, w):
        if re.fullmatch(_NUMBER, w):
            total, used = float(w), 1
        elif w in _TENS_WORDS:
            total, used = _TENS_WORDS[w], 1
            if nxt in _UNITS_WORDS and 0 < _UNITS_WORDS[nxt] < 10:
                total += _UNITS_WORDS[nxt]
                used = 2
            elif "-" in nxt:
                pass
        else:
            total, used = _UNITS_WORDS[w], 1
        if i + used < len(words) and words[i + used] == "hundred":
            total *= 100
            used += 1
        # "one and a half", "two and a quarter"
        rest = words[i + used : i + used + 3]
        if len(rest) == 3 and rest[0] == "and" and rest[1] in ("a", "one") and rest[2] in _FRACTIONS:
            total += _FRACTIONS[rest[2]]
            used += 3
        return total, used
    if "-" in w:  # "twenty-five"
        a, _, b = w.partition("-")
        if a in _TENS_WORDS and b in _UNITS_WORDS:
            return _TENS_WORDS[a] + _UNITS_WORDS[b], 1
    return 0.0, 0


@dataclass(frozen=True)
class Quantity:
    """An amount said with the motion: metres, degrees or steps (one of them), or "a bit"."""

    metres: float | None = None
    degrees: float | None = None
    steps: float | None = None
    small: bool = False
    text: str = ""
    times: float | None = None  # "twice", "3 times": the motion said without an amount, repeated

    def length_m(self) -> float:
        """The distance to walk [m] (a step is :data:`STEP_M`, "a bit" :data:`SMALL_M`)."""
        if self.metres is not None:
            return self.metres
        if self.steps is not None:
            return self.steps * STEP_M
        return (SMALL_M if self.small else STEP_M) * (self.times or 1.0)

    def angle_deg(self, default: float = 90.0) -> float:
        """The angle to turn [deg] (``default`` when none was said: 90, or 180 for "around")."""
        if self.degrees is not None:
            return self.degrees
        return (SMALL_DEG if self.small else default) * (self.times or 1.0)


_QUANTITY = re.compile(
    rf"\b(?:by |about |around |roughly |some )?(?P<n>{_NUMBER}|a|an|one)\s*"
    r"(?P<unit>°|(?:[a-z]+)\b)"
)
_SMALL = re.compile(
    r"\b(?:a (?:little|tiny) bit|a little|a bit|a tad|slightly|a touch|a smidge|"
    r"a few (?:centimet(?:er|re)s|cm))\b"
)
_TURN = re.compile(
    r"\b(?:a |one )?(?P<frac>quarter|half|full|whole|complete)[ -]?"
    r"(?:turn|circle|rotation|way round|way around)\b"
)


def take_quantity(text: str) -> tuple[Quantity | None, str]:
    """The first quantity in ``text`` (digits already, see :func:`words_to_digits`) and the text
    without it. Recognises lengths, angles, steps, turn fractions and "a bit"."""
    m = _TURN.search(text)
    if m:
        return Quantity(degrees=TURN_WORDS[m["frac"]], text=m.group(0)), _cut(text, m)
    for m in _QUANTITY.finditer(text):
        unit = m["unit"]
        raw = m["n"]
        n = 1.0 if raw in ("a", "an", "one") else float(raw)
        if unit in LENGTH_UNITS and not (unit == "in" and raw in ("a", "an")):
            if unit == "in" and not re.fullmatch(_NUMBER, raw):
                continue
            return Quantity(metres=n * LENGTH_UNITS[unit], text=m.group(0)), _cut(text, m)
        if unit in ANGLE_UNITS:
            return Quantity(degrees=n * ANGLE_UNITS[unit], text=m.group(0)), _cut(text, m)
        if unit in ("step", "steps", "pace", "paces"):
            return Quantity(steps=n, text=m.group(0)), _cut(text, m)
        if unit in ("turn", "turns", "revolution", "revolutions") and re.fullmatch(_NUMBER, raw):
            return Quantity(degrees=n * 360.0, text=m.group(0)), _cut(text, m)
        if unit in ("time", "times") and re.fullmatch(_NUMBER, raw):
            return Quantity(times=n, text=m.group(0)), _cut(text, m)
    m = re.search(rf"\b(?:by )?(?P<n>{_NUMBER})\b", text)
    if m:  # a bare number: its unit depends on the motion (degrees for a turn, metres for a walk)
        return Quantity(metres=float(m["n"]), degrees=float(m["n"]), text=m.group(0)), _cut(text, m)
    m = _SMALL.search(text)
    if m:
        return Quantity(small=True, text=m.group(0)), _cut(text, m)
    return None, text


def _cut(text: str, m: re.Match[str]) -> str:
    return " ".join((text[: m.start()] + " " + text[m.end() :]).split())
