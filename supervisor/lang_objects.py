"""Object phrases: "the orange ball", "the ball", "the orange one", "that", "the desk" -> a known object.

Known objects are perception's names, ``<colour>_<kind>`` or ``<kind>`` (``orange_ball``,
``yellow_table``, ``chair``). A phrase names a colour, a kind (with synonyms: desk is a table, cube a
box), both, or refers back ("it", "that"). :func:`resolve` gives one name, or the candidates when
several fit (the console then asks which), or none with the reason.
"""

from __future__ import annotations

import difflib
from dataclasses import dataclass

COLOURS = (
    "orange",
    "green",
    "yellow",
    "blue",
    "red",
    "white",
    "black",
    "purple",
    "pink",
    "brown",
    "grey",
    "gray",
    "cyan",
    "magenta",
)
#: Words people use for a kind of object -> the kind in the object names.
KIND_SYNONYMS = {
    "ball": "ball",
    "balls": "ball",
    "sphere": "ball",
    "orb": "ball",
    "box": "box",
    "boxes": "box",
    "cube": "box",
    "crate": "box",
    "block": "box",
    "carton": "box",
    "table": "table",
    "tables": "table",
    "desk": "table",
    "counter": "table",
    "chair": "chair",
    "chairs": "chair",
    "seat": "chair",
    "stool": "chair",
}
PRONOUNS = (
    "it",
    "that",
    "this",
    "them",
    "that one",
    "this one",
    "the object",
    "the thing",
    "same one",
    "the same one",
    "the same",
)
DETERMINERS = {
    "the",
    "a",
    "an",
    "this",
    "that",
    "those",
    "these",
    "my",
    "your",
    "our",
    "some",
    "its",
    "one",
    "thing",
    "object",
    "please",
}
#: Adjectives that do not tell objects apart here.
IGNORED_ADJECTIVES = {
    "big",
    "small",
    "little",
    "large",
    "tiny",
    "round",
    "square",
    "nice",
    "same",
    "other",
    "colored",
    "coloured",
    "whole",
}


@dataclass(frozen=True)
class ObjectRef:
    """What an object phrase resolved to: ``name``, or ``candidates`` (ambiguous), or ``problem``."""

    phrase: str
    name: str = ""
    candidates: tuple[str, ...] = ()
    problem: str = ""
    pronoun: bool = False


def spoken(name: str) -> str:
    """``orange_ball`` -> ``orange ball``."""
    return name.replace("_", " ")


def _parts(name: str) -> tuple[str, str]:
    """``(colour, kind)`` of a known name (colour "" when it has none)."""
    words = name.split("_")
    if len(words) >= 2 and words[0] in COLOURS:
        return words[0], "_".join(words[1:])
    return "", name


def _typo_of(word: str, vocabulary: tuple[str, ...] | dict[str, str], *, changed_letter: bool = True) -> str:
    """The word of ``vocabulary`` (of 4 letters or more) that ``word`` is a typing slip of: one letter
    missing, added or swapped with its neighbour, or (``changed_letter``) one letter changed; or ""."""
    if len(word) < 3:
        return ""
    for known in vocabulary:
        if len(known) < 4 or edit_distance(word, known) != 1:
            continue
        if changed_letter or len(word) != len(known) or sorted(word) == sorted(known):
            return known
    return ""


def edit_distance(a: str, b: str) -> int:
    """Optimal string alignment distance (a swap of two neighbours counts 1): "tkae" -> "take" is 1."""
    d = [[i + j if i * j == 0 else 0 for j in range(len(b) + 1)] for i in range(len(a) + 1)]
    for i in range(1, len(a) + 1):
        for j in range(1, len(b) + 1):
            cost = a[i - 1] != b[j - 1]
            d[i][j] = min(d[i - 1][j] + 1, d[i][j - 1] + 1, d[i - 1][j - 1] + cost)
            if i > 1 and j > 1 and a[i - 1] == b[j - 2] and a[i - 2] == b[j - 1]:
                d[i][j] = min(d[i][j], d[i - 2][j - 2] + 1)
    return d[len(a)][len(b)]


def resolve(phrase: str, known: list[str] | tuple[str, ...], referent: str | None = None) -> ObjectRef:
    """Resolve an object phrase against the known names; ``referent`` is what "it"/"that" means now."""
    text = " ".join(phrase.split())
    if text in PRONOUNS or text.removeprefix("the ") in ("same", "same one"):
        if referent:
            return ObjectRef(phrase, name=referent, pronoun=True)
        return ObjectRef(phrase, problem=f"I don't know what '{text}' is: name the object", pronoun=True)
    if text.replace(" ", "_") in known:
        return ObjectRef(phrase, name=text.replace(" ", "_"))
    words = [w for w in text.replace("_", " ").split() if w not in DETERMINERS]
    if "_".join(words) in known:  # "the red cup", "the coffee mug": a learned object's own name
        return ObjectRef(phrase, name="_".join(words))
    # the kinds of the known objects are words too ("cup" of red_cup; "mug" of coffee_mug), beyond the
    # synonyms' table
    known_kinds = {kind.rsplit("_", 1)[-1]: kind for kind in (_parts(k)[1] for k in known)}
    colour = ""
    kind = ""
    unknown: list[str] = []
    for w in words:
        if w in COLOURS:
            colour = "grey" if w == "gray" else w
        elif w in KIND_SYNONYMS:
            kind = KIND_SYNONYMS[w]
        elif w in known_kinds or (w.endswith("s") and w[:-1] in known_kinds):
            kind = known_kinds[w if w in known_kinds else w[:-1]]
        elif w.endswith("ish") and w[:-3] in COLOURS:
            colour = w[:-3]
        elif w in IGNORED_ADJECTIVES:
            continue
        elif typo := _typo_of(w, COLOURS):  # "ornge": a typed colour one letter off
            colour = "grey" if typo == "gray" else typo
        elif typo := _typo_of(w, KIND_SYNONYMS, changed_letter=False):  # "bal", "tabel"; not "cable"
            kind = KIND_SYNONYMS[typo]
        else:
            unknown.append(w)
    if not colour and not kind:
        if unknown:
            hint = difflib.get_close_matches(" ".join(unknown), [spoken(k) for k in known], n=1, cutoff=0.6)
            extra = f" (did you mean the {hint[0]}?)" if hint else ""
            return ObjectRef(phrase, problem=f"I don't know '{' '.join(unknown)}'{extra}")
        return ObjectRef(phrase, problem="which object?")
    if unknown and not kind:  # "the orange cup": a colour and a noun we do not know
        return ObjectRef(phrase, problem=f"I don't know a {' '.join([colour, *unknown]).strip()}")
    candidates = tuple(
        k for k in known if (not colour or _parts(k)[0] == colour) and (not kind or _parts(k)[1] == kind)
    )
    if len(candidates) == 1:
        return ObjectRef(phrase, name=candidates[0])
    if candidates:
        return ObjectRef(phrase, candidates=candidates)
    said = " ".join(w for w in (colour, kind) if w) or text
    return ObjectRef(phrase, problem=f"I don't know a {said}")


def question(ref: ObjectRef) -> str:
    """ "which ball: the orange one or the blue one?" for an ambiguous reference."""
    parts = [_parts(c) for c in ref.candidates]
    kinds = {k for _, k in parts}
    colours = {c for c, _ in parts}
    if len(kinds) == 1 and all(colours):
        kind = kinds.pop()
        options = [f"the {c} one" for c, _ in parts]
        head = f"which {kind}"
    elif len(colours) == 1 and "" not in colours:
        colour = colours.pop()
        options = [f"the {k}" for _, k in parts]
        head = f"which {colour} one"
    else:
        options = [f"the {spoken(c)}" for c in ref.candidates]
        head = "which one"
    listed = ", ".join(options[:-1]) + f" or {options[-1]}" if len(options) > 1 else options[0]
    return f"{head}: {listed}?"


_ORDINALS = {
    "first": 0,
    "1st": 0,
    "second": 1,
    "2nd": 1,
    "third": 2,
    "3rd": 2,
    "last": -1,
    "former": 0,
    "latter": -1,
}


def answer(text: str, candidates: tuple[str, ...]) -> str | None:
    """The candidate a reply to :func:`question` picks ("the orange one", "blue", "the first"), or None."""
    words = text.split()
    for w in words:
        if w in _ORDINALS:
            index = _ORDINALS[w]
            return candidates[index] if -len(candidates) <= index < len(candidates) else None
    ref = resolve(text, candidates)
    return ref.name or None
