"""What people say to the robot -> supervisor steps: a small grammar, and a conversation's memory.

A line is split into clauses (``,``, "and", "then", "after that"); each clause loses its politeness
and filler ("please", "could you", "for me", "now", "wait,") and is parsed as

    clause := VERB [OBJECT] [PREPOSITION PLACE] [DIRECTION] [QUANTITY] [HAND]

in any order after the verb. The verb is looked up in :data:`VERBS` (synonyms: take/grab/get/pick
up/fetch; go/walk/head/move to; put/place/drop/set/leave on; release/let go/open; look at;
find/where is/can you see; turn/rotate; step/back up); the object phrase is resolved by
:mod:`supervisor.lang_objects` (colour, kind, both, or "it"/"that"); numbers and units by
:mod:`supervisor.lang_numbers`. Each understood clause (an :class:`Intent`) becomes the steps of the
script language (:mod:`supervisor.script`), so the console runs exactly what a script would.

:class:`Listener` keeps what a conversation needs between lines: what is held, what was named last,
and an open question ("which ball: the orange one or the blue one?") that the next line answers.
Nothing here touches the bus.
"""

from __future__ import annotations

import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace

from supervisor.lang_numbers import STEP_M, Quantity, take_quantity, words_to_digits
from supervisor.lang_objects import (
    COLOURS,
    DETERMINERS,
    KIND_SYNONYMS,
    ObjectRef,
    answer,
    edit_distance,
    question,
    resolve,
    spoken,
)
from supervisor.script import ACTIONS, EITHER_HAND, Signature, Step

#: Verb phrases -> what they mean. Longer phrases are tried first.
VERBS: dict[str, str] = {
    # take
    "pick up": "take",
    "pick": "take",
    "take hold of": "take",
    "get hold of": "take",
    "grab": "take",
    "grasp": "take",
    "take": "take",
    "get": "take",
    "fetch": "take",
    "collect": "take",
    "lift": "take",
    "hold": "take",
    "retrieve": "take",
    "seize": "take",
    "snatch": "take",
    "catch": "take",
    "bring": "bring",
    "give me": "bring",
    "hand me": "bring",
    "pass me": "bring",
    "give": "bring",
    "i want": "take",
    "i need": "take",
    "i would like": "take",
    "can i have": "take",
    "could i have": "take",
    "may i have": "take",
    "go get": "take",
    "go fetch": "take",
    "go grab": "take",
    "go pick up": "take",
    "go and get": "take",
    "go and fetch": "take",
    "go and grab": "take",
    "go and pick up": "take",
    "come and get": "take",
    "carry": "bring",
    "deliver": "bring",
    # go
    "go": "go",
    "walk": "go",
    "head": "go",
    "move": "go",
    "approach": "go",
    "navigate": "go",
    "proceed": "go",
    "come": "go",
    "run": "go",
    "travel": "go",
    "drive": "go",
    "get over": "go",
    "make your way": "go",
    "get going": "go",
    # put
    "put down": "put",
    "set down": "put",
    "place down": "put",
    "lay down": "put",
    "put": "put",
    "place": "put",
    "set": "put",
    "drop": "put",
    "drop off": "put",
    "leave": "put",
    "lay": "put",
    "deposit": "put",
    "rest": "put",
    "stick": "put",
    # release
    "let go of": "release",
    "let go": "release",
    "let it go": "release",
    "let that go": "release",
    "release": "release",
    "open": "release",
    "unclench": "release",
    "ungrasp": "release",
    # look / find
    "look at": "look",
    "look toward": "look",
    "look towards": "look",
    "glance at": "look",
    "point your head at": "look",
    "look": "look",
    "face": "face",
    "look for": "find",
    "look around for": "find",
    "search for": "find",
    "search": "find",
    "where is": "find",
    "where are": "find",
    "is there": "find",
    "find": "find",
    "locate": "find",
    "see": "find",
    "spot": "find",
    "detect": "find",
    "show me": "find",
    "check for": "find",
    # turn
    "turn around": "turn",
    "turn": "turn",
    "rotate": "turn",
    "spin": "turn",
    "pivot": "turn",
    "swivel": "turn",
    "spin around": "turn",
    # relative steps
    "take a step": "step",
    "make a step": "step",
    "do a step": "step",
    "step": "step",
    "sidestep": "step",
    "side step": "step",
    "shuffle": "step",
    "scoot": "step",
    "shift": "step",
    "back up": "back",
    "back off": "back",
    "back away": "back",
    "reverse": "back",
    "retreat": "back",
    # posture
    "stand up": "stand",
    "get out of": "stand",
    "get off": "stand",
    "climb out of": "stand",
    "get up": "stand",
    "stand": "stand",
    "rise": "stand",
    "get back up": "stand",
    # light verbs: "make a quarter turn", "do a step to the left"
    "make": "light",
    "do": "light",
    "perform": "light",
    # control
    "stop": "stop",
    "halt": "stop",
    "freeze": "stop",
    "abort": "stop",
    "cancel": "stop",
    "stop everything": "stop",
    "wait": "stop",
    "hold on": "stop",
    "stay": "stop",
    "help": "help",
    "help me": "help",
    "what can you do": "help",
    "what do you understand": "help",
    "quit": "quit",
    "exit": "quit",
    "bye": "quit",
    "goodbye": "quit",
    "good bye": "quit",
}
_VERB_LIST = sorted(VERBS, key=lambda v: -len(v.split()))

#: Politeness and filler dropped at the start of a clause (longest first) and at its end.
LEADING_FILLER = (
    "would you be so kind as to",
    "would you mind",
    "i would like you to",
    "i want you to",
    "i need you to",
    "could you please",
    "can you please",
    "would you please",
    "will you please",
    "could you",
    "can you",
    "would you",
    "will you",
    "do you",
    "are you able to",
    "you should",
    "you can",
    "you could",
    "go ahead and",
    "try to",
    "please",
    "kindly",
    "now",
    "wait",
    "ok",
    "okay",
    "alright",
    "all right",
    "so",
    "well",
    "hey",
    "hi",
    "hello",
    "robot",
    "hrp2",
    "hrp",
    "um",
    "uh",
    "er",
    "just",
    "also",
    "first",
    "firstly",
    "then",
    "and",
    "finally",
    "next",
    "afterwards",
    "after that",
    "lastly",
    "oh",
    "right",
    "let us",
    "lets",
    "quickly",
    "carefully",
    "slowly",
    "gently",
    "again",
)
TRAILING_FILLER = (
    "please",
    "for me",
    "now",
    "thanks",
    "thank you",
    "right now",
    "if you can",
    "if you could",
    "if possible",
    "ok",
    "okay",
    "quickly",
    "carefully",
    "slowly",
    "gently",
    "again",
    "as well",
    "too",
    "straight away",
    "right away",
    "immediately",
    "then",
    "first",
)
#: A line of only these means "stop" (inside a line they are filler: "wait, take the ball").
WAIT_WORDS = ("wait", "hold on", "wait a moment", "wait a second", "one moment", "hang on")
#: A line of only these drops an open question and does nothing.
NEVER_MIND = ("never mind", "nevermind", "forget it", "forget that", "nothing", "no", "nope")
_CONTRACTIONS = {
    "what's": "what is",
    "where's": "where is",
    "let's": "let us",
    "i'd": "i would",
    "it's": "it is",
    "that's": "that is",
    "don't": "do not",
    "can't": "cannot",
    "won't": "will not",
    "you're": "you are",
    "i'm": "i am",
    "there's": "there is",
}
_CLAUSE_SPLIT = re.compile(
    r"\s*[,;:]\s*|\s+(?:and then|and after that|and afterwards|after that|afterwards|then|and|"
    r"and finally|finally|next(?!\s+to\b)|followed by)\s+"
)
_DIRECTIONS = {
    "left": "left",
    "leftward": "left",
    "leftwards": "left",
    "right": "right",
    "rightward": "right",
    "rightwards": "right",
    "forward": "forward",
    "forwards": "forward",
    "ahead": "forward",
    "straight": "forward",
    "onward": "forward",
    "back": "back",
    "backward": "back",
    "backwards": "back",
    "behind": "back",
    "around": "around",
    "round": "around",
    "clockwise": "right",
    "counterclockwise": "left",
    "anticlockwise": "left",
    "counter clockwise": "left",
    "anti clockwise": "left",
    "sideways": "side",
}
_DIRECTION = re.compile(
    r"\b(?:to |towards |toward )?(?:the |your |my )?(?P<d>counter clockwise|anti clockwise|"
    + "|".join(sorted((d for d in _DIRECTIONS if " " not in d), key=len, reverse=True))
    + r")\b(?: side)?"
)
_HAND = re.compile(
    r"\b(?:with|using|in|by) (?:your |the |my |its )?(?P<h>left|right) (?:hand|arm|gripper)\b|"
    r"\b(?P<h2>left|right)[- ]handed\b"
)
_PLACE_PREP = re.compile(r"\s+(?:down )?(?:on top of|onto|on to|upon|on|into|in|inside|at|over|atop)\s+")
_GOAL_PREP = re.compile(
    r"^(?:back )?(?:over )?(?:to|towards|toward|up to|near|next to|close to|in front of|by|"
    r"the way to|over)\s+"
)
_RECIPIENT = re.compile(r"\b(?:to me|for me|over here|here|to us|back here)\b|^me\b|^us\b")
_PLACE_KINDS = ("table", "box", "chair")
#: The name a take binds to what the hand grasped (``grasp right as held``); a put of "it" when this
#: conversation does not know what is held refers to it (the runner keeps bindings between lines).
HELD = "held"
CAN_DO = (
    "I can: take X, go to X, put it on X, bring X to Y, release, look at X, find X, "
    "turn left/right [N degrees], step or move forward/back/left/right [N m], stop, help"
)


@dataclass(frozen=True)
class Intent:
    """One understood clause: ``kind`` (take, bring, go, put, release, look, find, turn, walk, stand)
    and its resolved arguments."""

    kind: str
    clause: str
    obj: str = ""
    place: str = ""
    forward_m: float = 0.0
    left_m: float = 0.0
    angle_deg: float = 0.0
    hand: str = ""

    def summary(self) -> str:
        o, p = ("what I hold" if self.obj == HELD else spoken(self.obj)), spoken(self.place)
        return {
            "take": f"take the {o}",
            "bring": f"bring {o if self.obj == HELD else 'the ' + o} to the {p}",
            "go": f"go to the {o}",
            "put": f"put {o if self.obj == HELD else 'the ' + o} on the {p}",
            "release": f"release what the {self.hand} hand holds",
            "look": f"look at the {o}",
            "find": f"find the {o}",
            "turn": "turn around (180 degrees)"
            if self.angle_deg == 180
            else f"turn {abs(self.angle_deg):g} degrees {'left' if self.angle_deg >= 0 else 'right'}",
            "walk": _walk_text(self.forward_m, self.left_m),
            "stand": "stand up",
        }.get(self.kind, self.kind)


def _walk_text(forward_m: float, left_m: float) -> str:
    parts = []
    if forward_m:
        parts.append(f"{abs(forward_m):g} m {'forward' if forward_m > 0 else 'back'}")
    if left_m:
        parts.append(f"{abs(left_m):g} m to the {'left' if left_m > 0 else 'right'}")
    return "walk " + " and ".join(parts or ["0 m"])


@dataclass(frozen=True)
class Understanding:
    """What one line means: steps to run, a control word, or something to say (a question, a refusal).

    ``understood`` lists the clauses understood, in words; ``say`` is the question or the refusal.
    """

    text: str
    steps: tuple[Step, ...] = ()
    control: str = ""  # "stop" | "help" | "quit" | "ask" (a question was asked) | ""
    say: str = ""
    understood: tuple[str, ...] = ()
    refused: bool = False

    def explain(self) -> str:
        """The steps this line would run, one per line (for ``humanoid console --explain``)."""
        lines = [f"> {self.text}"]
        if self.understood:
            lines.append("understood: " + "; ".join(self.understood))
        if self.control and self.control != "ask":
            lines.append(f"control: {self.control}")
        if self.say:
            lines.append(("refused: " if self.refused else "asks: ") + self.say)
        for i, step in enumerate(self.steps, start=1):
            lines.append(f"  {i}. {step.text()}")
        return "\n".join(lines)


class NotUnderstoodError(Exception):
    """A clause that could not be understood; ``reason`` says what was missing."""

    def __init__(self, clause: str, reason: str) -> None:
        super().__init__(reason)
        self.clause = clause
        self.reason = reason


@dataclass
class _AskError(Exception):
    """A clause needs an answer: which object (``candidates``), where to put, or which way to turn."""

    what: str  # "obj" | "place" | "direction"
    prompt: str
    candidates: tuple[str, ...] = ()
    clause_index: int = 0


@dataclass
class _Context:
    held: str = ""
    last: str = ""
    last_place: str = ""


@dataclass
class _Pending:
    """An open question: the clauses of the line and the answer that fills one of them."""

    text: str
    clauses: list[str]
    index: int
    what: str
    candidates: tuple[str, ...]
    filled: dict[int, dict[str, str]] = field(default_factory=dict)


def normalize(text: str) -> str:
    """Lower case, contractions expanded, number words as digits, punctuation reduced to clause
    separators (``,``), units glued to their numbers read apart (``45°`` -> ``45 °``)."""
    line = text.lower().replace("’", "'").replace("`", "'")
    for short, full in _CONTRACTIONS.items():
        line = re.sub(rf"\b{re.escape(short)}", full, line)
    line = re.sub(r"(\d)\s*°", r"\1 °", line)
    line = re.sub(r"(\d)(cm|mm|m|deg|ft)\b", r"\1 \2", line)
    line = re.sub(r"[!?]+", " ", line)
    line = re.sub(r"\.(?!\d)", ",", line)  # a full stop ends a clause; "0.5" stays
    line = re.sub(r"[^a-z0-9_.,;:°' -]", " ", line)
    line = line.replace("'", " ").replace(" - ", " , ")
    line = re.sub(r"\s+", " ", line).strip(" ,;:")
    return words_to_digits(line)


def split_clauses(line: str) -> list[str]:
    return [c.strip() for c in _CLAUSE_SPLIT.split(line) if c and c.strip(" ,")]


def strip_filler(clause: str) -> str:
    """Drop politeness and filler around a clause ("could you please ... for me now")."""
    words = clause
    changed = True
    while changed:
        changed = False
        for f in LEADING_FILLER + TRAILING_FILLER:
            if words == f:
                return ""  # only filler ("hey robot,", "wait,")
        for f in LEADING_FILLER:
            if words.startswith(f + " "):
                words = words[len(f) + 1 :]
                changed = True
        for f in TRAILING_FILLER:
            if words.endswith(" " + f):
                words = words[: -len(f) - 1]
                changed = True
    return re.sub(r"\bplease\b", "", words).replace("  ", " ").strip()


def _verb(clause: str) -> tuple[str, str, str]:
    """``(kind, verb said, the rest)``; NotUnderstoodError when no verb is known (naming a close one)."""
    for verb in _VERB_LIST:
        if clause == verb or clause.startswith(verb + " "):
            rest = clause[len(verb) :].strip()
            if verb.endswith(" around"):  # "turn around": the direction is in the verb
                rest = f"around {rest}".strip()
            return VERBS[verb], verb, rest
    first, _, rest = clause.partition(" ")
    base = _base_form(first)
    if base != first:
        return _verb(f"{base} {rest}".strip())
    close = [v for v in VERBS if " " not in v and len(first) >= 4 and edit_distance(first, v) <= 1]
    if close:
        suggestion = " ".join([close[0], rest]).strip()
        raise NotUnderstoodError(clause, f"'{first}' is no action I know. The closest I know: '{suggestion}'")
    raise NotUnderstoodError(clause, "I found no action in it")


def _base_form(word: str) -> str:
    """The verb a gerund or third person stands for: grabbing -> grab, taking -> take, turns -> turn."""
    single = {v for v in VERBS if " " not in v}
    candidates = []
    if word.endswith("ing"):
        stem = word[:-3]
        candidates += [stem, stem + "e", stem[:-1] if len(stem) > 2 and stem[-1] == stem[-2] else ""]
    if word.endswith("s"):
        candidates += [word[:-1], word[:-2] if word.endswith("es") else ""]
    for c in candidates:
        if c and c in single:
            return c
    return word


def _is_amount(text: str) -> bool:
    """Whether ``text`` is only an amount ("0.5 m", "a bit", "2 steps"), not a place."""
    quantity, left = take_quantity(text)
    return quantity is not None and not left.strip()


def _take_hand(rest: str) -> tuple[str, str]:
    m = _HAND.search(rest)
    if not m:
        return "", rest
    return m["h"] or m["h2"], " ".join((rest[: m.start()] + " " + rest[m.end() :]).split())


def _take_direction(rest: str) -> tuple[str, str]:
    m = _DIRECTION.search(rest)
    if not m:
        return "", rest
    return _DIRECTIONS[m["d"]], " ".join((rest[: m.start()] + " " + rest[m.end() :]).split())


class Listener:
    """Understands the lines of one conversation (a console session)."""

    def __init__(
        self,
        known_objects: Sequence[str],
        hand: str = EITHER_HAND,
        actions: Mapping[str, Signature] | None = None,
    ) -> None:
        self.known = list(known_objects)
        self.hand = hand
        self.actions = ACTIONS if actions is None else actions
        self.ctx = _Context()
        self._pending: _Pending | None = None

    # -------------------------------------------------------------------------------------- public
    def hear(self, text: str) -> Understanding:
        """What ``text`` means now (it may answer the last question)."""
        line = normalize(text)
        if self._pending is not None:
            pending, self._pending = self._pending, None
            reply = self._answer(pending, line, text)
            if reply is not None:
                return reply
        clauses = [c for c in split_clauses(line) if strip_filler(c)]
        while len(clauses) > 1 and strip_filler(clauses[0]) in ("go", "come", "come on"):
            clauses = clauses[1:]  # "go and take the ball"
        if line in WAIT_WORDS:
            return Understanding(text, control="stop", understood=("stop",))
        if line in NEVER_MIND:
            return Understanding(text, say="OK, never mind.")
        if strip_filler(line) == "" and re.search(r"\bthank", line):
            return Understanding(text, say="You're welcome.")
        if not clauses:
            return Understanding(text, refused=True, say="I heard nothing to do. " + CAN_DO + ".")
        named = self._only_an_object(clauses)
        if named:  # "the purple one" with no question open: which action? "it" is that object now
            self.ctx.last = named
            return Understanding(
                text,
                refused=True,
                say=f"What should I do with the {spoken(named)}? For example: take it, look at it, go to it.",
            )
        return self._understand(text, clauses, {})

    def _only_an_object(self, clauses: list[str]) -> str:
        """The object a line names when it is nothing but an object phrase ("the blue one"), else ""."""
        if len(clauses) != 1:
            return ""
        clause = strip_filler(clauses[0])
        first = clause.split()[0] if clause else ""
        named = (w for k in self.known for w in k.split("_"))
        object_words = {*DETERMINERS, *COLOURS, *KIND_SYNONYMS, *named}
        if first not in object_words:  # "juggle the ball", "tkae the ball": a verb not understood
            return ""
        try:
            _verb(clause)
            return ""
        except NotUnderstoodError:
            return resolve(clause, self.known).name

    def forget_held(self) -> None:
        """The hand is empty after all (a take failed, or the object was dropped)."""
        self.ctx.held = ""

    @property
    def asking(self) -> bool:
        return self._pending is not None

    # ------------------------------------------------------------------------------------- answers
    def _answer(self, pending: _Pending, line: str, said: str) -> Understanding | None:
        reply = strip_filler(line.replace(",", " ").strip())
        filled = dict(pending.filled)
        if pending.what == "direction":
            direction, _ = _take_direction(reply)
            if direction not in ("left", "right"):
                return None
            value = direction
        else:
            words = reply
            for prefix in ("on the ", "onto the ", "on ", "onto ", "in the ", "the "):
                if pending.what == "place" and words.startswith(prefix):
                    words = words[len(prefix) - (4 if prefix.endswith("the ") else 0) :]
                    break
            value = answer(words, pending.candidates) if pending.candidates else ""
            if not value and pending.what == "place":
                ref = resolve(words, self.known)
                value = ref.name
            if not value:
                return None
        filled[pending.index] = {**filled.get(pending.index, {}), pending.what: value}
        return self._understand(
            f"{said.strip()} (answering: {pending.text.strip()})", pending.clauses, filled
        )

    # -------------------------------------------------------------------------------- understanding
    def _understand(self, text: str, clauses: list[str], filled: dict[int, dict[str, str]]) -> Understanding:
        ctx = replace(self.ctx)
        previous = ""  # the verb of the clause before: "take the ball, then the box" reuses it
        intents: list[Intent] = []
        understood: list[str] = []
        for index, raw in enumerate(clauses):
            clause = strip_filler(raw)
            try:
                kind, verb, rest = self._verb_or_ellipsis(clause, previous)
                if kind in ("stop", "help", "quit"):
                    if rest and kind != "stop":
                        raise NotUnderstoodError(clause, f"'{verb}' takes nothing after it")
                    note = "" if len(clauses) == 1 else f" (the rest of '{text.strip()}' is dropped)"
                    return Understanding(text, control=kind, say=note.strip(), understood=(kind,))
                intent = self._parse(kind, verb, rest, clause, ctx, filled.get(index, {}))
            except _AskError as ask:
                self._pending = _Pending(text, clauses, index, ask.what, ask.candidates, filled)
                return Understanding(text, control="ask", say=ask.prompt, understood=tuple(understood))
            except NotUnderstoodError as exc:
                exc.clause = clause
                return self._refuse(text, exc, understood)
            intents.extend(self._expand(intent, ctx))
            understood.append(intent.summary())
            previous = verb
        steps: list[Step] = []
        for intent in intents:
            for step in self._steps(intent):
                if not (step.action == "localize" and steps and steps[-1] == step):  # found just now
                    steps.append(step)
        missing = sorted({s.action for s in steps if s.action not in self.actions})
        if missing:
            return Understanding(
                text,
                refused=True,
                understood=tuple(understood),
                say=f"I understood: {'; '.join(understood)}; but this supervisor has no "
                f"{' or '.join(repr(a) for a in missing)} action (actions: {', '.join(self.actions)}).",
            )
        self.ctx = ctx
        return Understanding(text, steps=tuple(steps), understood=tuple(understood))

    def _verb_or_ellipsis(self, clause: str, previous: str) -> tuple[str, str, str]:
        """The clause's verb; a clause that is only an object phrase repeats the verb before it."""
        try:
            return _verb(clause)
        except NotUnderstoodError:
            if previous and previous not in ("stop", "help", "quit"):
                ref = resolve(clause, self.known)
                if ref.name or ref.candidates:
                    return VERBS[previous], previous, clause
            raise

    def _refuse(self, text: str, exc: NotUnderstoodError, understood: list[str]) -> Understanding:
        said = f"I understood: {'; '.join(understood)}. " if understood else ""
        known = ", ".join(spoken(k) for k in self.known)
        return Understanding(
            text,
            refused=True,
            understood=tuple(understood),
            say=f"{said}I did not understand '{exc.clause}': {exc.reason}. {CAN_DO}. Known objects: {known}.",
        )

    def _object(self, phrase: str, referent: str, what: str, filled: Mapping[str, str]) -> str:
        """A known object name for ``phrase``; _AskError when ambiguous, NotUnderstoodError when unknown."""
        if what in filled:
            return filled[what]
        phrase = phrase.strip()
        if not phrase:
            if referent:
                return referent
            raise NotUnderstoodError(phrase, "which object?")
        ref: ObjectRef = resolve(phrase, self.known, referent or None)
        if ref.name:
            return ref.name
        if ref.candidates:
            raise _AskError(what, question(ref), ref.candidates)
        raise NotUnderstoodError(phrase, ref.problem)

    def _parse(
        self, kind: str, verb: str, rest: str, clause: str, ctx: _Context, filled: Mapping[str, str]
    ) -> Intent:
        hand, rest = _take_hand(rest)
        hand = hand or self.hand
        step = re.match(
            r"^(?:(?:a|an|\d+(?:\.\d+)?) )?(?P<size>(?:small|little|tiny|short|baby) )?(?:steps?|paces?)\b",
            rest,
        )
        if kind == "take" and step:
            kind = "step"
            rest = re.sub(r"^(?:a |an )?(?:small |little |tiny |short |baby )?", "", rest)
            if step["size"] and not re.match(r"^\d", rest):
                rest = "a bit " + re.sub(r"^(?:steps?|paces?)\b", "", rest)
        if kind == "take" and verb == "get" and (rest.startswith("to ") or rest.startswith("over to ")):
            kind = "go"
        if kind == "go" and re.match(r"^(?:up|back up)$", rest) and verb == "get":
            kind = "stand"
        if kind == "light":
            if re.search(r"\b(?:turn|rotation|spin|circle)\b", rest):
                kind = "turn"
                rest = re.sub(r"^(?:a |an )?", "", re.sub(r"\b(?:turn|rotation|spin|circle)\b", "turn", rest))
            elif re.search(r"\b(?:steps?|paces?)\b", rest):
                kind, rest = "step", re.sub(r"\b(?:a |an )?(?:steps?|paces?)\b", "", rest).strip()
            else:
                raise NotUnderstoodError(clause, f"'{verb} {rest}' is not an action I can do")
        if kind in ("take", "bring"):
            return self._parse_take(kind, rest, clause, ctx, filled, hand)
        if kind == "go":
            return self._parse_go(rest, clause, ctx, filled, verb)
        if kind == "put":
            return self._parse_put(verb, rest, clause, ctx, filled, hand)
        if kind == "release":
            # what is released is whatever the hand holds: the object named does not change the step;
            # the hand may be the object ("open the left hand", "release your right gripper")
            side = re.search(r"\b(?P<h>left|right)\b(?: (?:hand|gripper|arm|one|side))?", rest)
            return Intent("release", clause, hand=side["h"] if side else hand)
        if kind in ("look", "find"):
            rest = re.sub(r"^(?:at|for|around for|around|to|towards|toward)\b", "", rest).strip()
            rest = re.sub(
                r"\b(?:anywhere|somewhere|around|nearby|over there|there|from here)$", "", rest
            ).strip()
            if kind == "look" and not rest:
                raise NotUnderstoodError(clause, "look at what? name an object")
            direction, left = _take_direction(rest)
            if kind == "look" and direction in ("left", "right") and not left:  # "look left": turn
                return self._parse_turn(rest, clause, filled)
            obj = self._object(rest, ctx.last, "obj", filled)
            return Intent(kind, clause, obj=obj)
        if kind == "face":
            direction, left = _take_direction(rest)
            if direction in ("left", "right", "back", "around") and not left:
                return self._parse_turn(rest, clause, filled)
            return Intent("look", clause, obj=self._object(rest, ctx.last, "obj", filled))
        if kind == "turn" and re.match(r"^(?:to |and )?face\b", rest):  # "turn to face the table"
            return Intent(
                "look",
                clause,
                obj=self._object(re.sub(r"^(?:to |and )?face\s*", "", rest), ctx.last, "obj", filled),
            )
        if kind == "turn":
            return self._parse_turn(rest, clause, filled)
        if kind in ("step", "back"):
            return self._parse_step(kind, rest, clause)
        if kind == "stand":  # the supervisor's stand_up: out of the chair, standing beside it
            rest = re.sub(r"^(?:back )?up\b\s*", "", rest)
            rest = re.sub(r"^(?:from|out of|off)\s+", "", rest)
            if rest and self._object(rest, "", "obj", filled) not in [k for k in self.known if "chair" in k]:
                raise NotUnderstoodError(clause, "I can stand up from the chair only")
            return Intent("stand", clause)
        raise NotUnderstoodError(clause, f"'{verb}' is not an action I can do")

    def _parse_take(
        self, kind: str, rest: str, clause: str, ctx: _Context, filled: Mapping[str, str], hand: str
    ) -> Intent:
        rest = re.sub(r"\bup\b", "", rest).strip()  # "pick the ball up"
        goal = ""
        m = re.search(r"\s(?:over )?(?:to|towards|toward|onto|on to|over to)\s+(?P<goal>.+)$", " " + rest)
        if m and not _RECIPIENT.fullmatch(m.group(0).strip()):
            goal = m["goal"].strip()
            rest = (" " + rest)[: m.start()].strip()
        # "bring me X", "X here": taken; the robot does not know where the person is, so it holds it
        rest = _RECIPIENT.sub("", rest).strip()
        rest = re.sub(r"\s+(?:on|from|off|in|at|near|beside|by)\s+.+$", "", rest)  # "the ball on the box"
        if goal and _RECIPIENT.fullmatch(goal):
            goal = ""
        if goal and rest in ("it", "that", "this") and not (ctx.held or ctx.last):
            obj = HELD  # "bring it to the table" in a new conversation: what the hand holds
        else:
            obj = self._object(rest, ctx.last, "obj", filled)
        if goal:
            place = self._object(goal, ctx.last_place, "place", filled)
            return Intent("bring", clause, obj=obj, place=place, hand=hand)
        return Intent("take", clause, obj=obj, hand=hand)

    def _parse_go(
        self, rest: str, clause: str, ctx: _Context, filled: Mapping[str, str], verb: str
    ) -> Intent:
        if verb == "come" and re.fullmatch(r"(?:back|here|over here|to me|back here|over)", rest):
            raise NotUnderstoodError(clause, "I do not know where you are: name a place or an object")
        sideways = re.match(r"^(?:to |towards |toward )(?:the |your |my )?(?:left|right)\b", rest)
        if (
            verb in ("move", "shift", "push", "slide")
            and not sideways
            and re.match(r"^(?:the|it|that|this)\b", rest)
        ) and re.search(
            r"\s(?:to|towards|toward|onto|on to|over to)\s", f" {rest} "
        ):  # "move the ball to the table"
            return self._parse_take("bring", rest, clause, ctx, filled, self.hand)
        m = None if sideways else _GOAL_PREP.match(rest)
        if m and _is_amount(rest[m.end() :]):  # "move back by 0.5 m": an amount, not a place
            m = None
        if m or (verb == "approach" and rest):
            goal = rest[m.end() :] if m else rest
            goal = re.sub(r"^(?:the )?(?:side of|front of)\s+", "", goal)
            if goal in ("here", "me", "us"):
                raise NotUnderstoodError(clause, "I do not know where you are: name a place or an object")
            return Intent("go", clause, obj=self._object(goal, ctx.last_place or ctx.last, "obj", filled))
        quantity, rest_q = take_quantity(rest)
        direction, left = _take_direction(rest_q)
        if direction:
            return self._walk(direction, quantity, clause, left)
        if quantity is not None and not left.strip():
            return self._walk("forward", quantity, clause, "")  # "walk 2 meters"
        if rest and not quantity:
            # "go the table", "head for the box"
            goal = re.sub(r"^(?:for|in)\s+", "", rest)
            return Intent("go", clause, obj=self._object(goal, ctx.last_place or ctx.last, "obj", filled))
        raise NotUnderstoodError(clause, "go where? name a place, or say forward/back/left/right")

    def _parse_put(
        self, verb: str, rest: str, clause: str, ctx: _Context, filled: Mapping[str, str], hand: str
    ) -> Intent:
        rest = re.sub(r"\bdown\b", "", rest).strip()
        parts = _PLACE_PREP.split(" " + rest + " ", maxsplit=1)
        obj_phrase = parts[0].strip()
        place_phrase = parts[1].strip() if len(parts) > 1 else ""
        if not place_phrase and obj_phrase.endswith(" there"):
            obj_phrase, place_phrase = obj_phrase[: -len(" there")], "there"
        if obj_phrase == "there":
            obj_phrase, place_phrase = "", "there"
        if not (ctx.held or ctx.last) and (not obj_phrase or obj_phrase in ("it", "that", "this")):
            obj = HELD  # what the hand holds, as the runner bound it
        elif ctx.held and ctx.held in resolve(obj_phrase, self.known).candidates:
            obj = ctx.held  # "put the ball on the table" holding the orange ball: the one in the hand
        else:
            obj = self._object(obj_phrase, ctx.held or ctx.last, "obj", filled)
        if place_phrase == "there" or place_phrase.startswith("there "):
            if not ctx.last_place:
                raise NotUnderstoodError(clause, "where is 'there'? name the place")
            return Intent("put", clause, obj=obj, place=ctx.last_place, hand=hand)
        if not place_phrase:
            if verb in ("drop", "let go", "release") or "place" in filled:
                if "place" in filled:
                    return Intent("put", clause, obj=obj, place=filled["place"], hand=hand)
                return Intent("release", clause, hand=hand)
            places = tuple(k for k in self.known if any(k.endswith(p) for p in _PLACE_KINDS) and k != obj)
            what = "it" if obj == HELD else f"the {spoken(obj)}"
            raise _AskError(
                "place",
                f"where should I put {what}? ({', '.join('on the ' + spoken(p) for p in places)})",
                places,
            )
        if place_phrase in ("itself", "it"):
            place = obj
        else:
            place = self._object(place_phrase, ctx.last_place, "place", filled)
        if place == obj:
            raise NotUnderstoodError(clause, f"I cannot put the {spoken(obj)} on itself")
        return Intent("put", clause, obj=obj, place=place, hand=hand)

    def _parse_turn(self, rest: str, clause: str, filled: Mapping[str, str]) -> Intent:
        negative = re.search(r"(?:^|\s)-\s*(?=\d)", rest)  # "turn -45": the scripts' sign, right
        if negative:
            rest = (rest[: negative.start()] + " " + rest[negative.end() :]).strip()
        quantity, rest = take_quantity(rest)
        direction, rest = _take_direction(rest)
        if negative:
            if direction:
                raise NotUnderstoodError(clause, "a negative angle and a direction: say one of them")
            direction = "right"
        if re.search(r"\b(?:to|towards|toward|at)\s+(?:the|a)\s+\w+", rest):
            raise NotUnderstoodError(
                clause,
                "I can turn by an angle (turn left 45 degrees) or look at an object, not turn toward it",
            )
        direction = filled.get("direction", direction)
        leftover = re.sub(
            r"\b(?:by|to|the|on the spot|in place|on the spot|yourself|your body|a|about)\b", "", rest
        ).strip()
        if leftover:
            raise NotUnderstoodError(clause, f"I do not know how to turn '{leftover}'")
        if direction in ("around", "back"):
            angle = quantity.angle_deg(180.0) if quantity else 180.0
            return Intent("turn", clause, angle_deg=angle)
        if direction not in ("left", "right"):
            if quantity is not None and quantity.degrees is not None and quantity.degrees in (180, 360):
                return Intent("turn", clause, angle_deg=quantity.degrees)  # the same either way
            raise _AskError("direction", "turn left or right?")
        angle = quantity.angle_deg(90.0) if quantity else 90.0
        return Intent("turn", clause, angle_deg=angle if direction == "left" else -angle)

    def _parse_step(self, kind: str, rest: str, clause: str) -> Intent:
        if re.search(r"\b(?:left|right)\b", rest):
            rest = re.sub(r"\bsideways\b", "", rest)  # "step sideways to the left"
        quantity, rest = take_quantity(rest)
        direction, rest = _take_direction(rest)
        if kind == "back":
            direction = direction or "back"
        if not direction:
            direction = "forward"
        if direction == "side":
            raise NotUnderstoodError(clause, "which side: left or right?")
        return self._walk(direction, quantity, clause, rest)

    def _walk(self, direction: str, quantity: Quantity | None, clause: str, leftover: str) -> Intent:
        leftover = re.sub(
            r"\b(?:by|a|an|the|of|up|more|further|away|off|yourself|to|one|over)\b", "", leftover
        ).strip()
        if leftover:
            raise NotUnderstoodError(clause, f"I do not know how to walk '{leftover}'")
        if direction == "around":
            return Intent("turn", clause, angle_deg=180.0)
        distance = quantity.length_m() if quantity else STEP_M
        forward = {"forward": distance, "back": -distance}.get(direction, 0.0)
        left = {"left": distance, "right": -distance}.get(direction, 0.0)
        return Intent("walk", clause, forward_m=round(forward, 3), left_m=round(left, 3))

    # -------------------------------------------------------------------------------------- steps
    def _expand(self, intent: Intent, ctx: _Context) -> list[Intent]:
        """An intent with what it implies (putting what is not held takes it first); updates ``ctx``."""
        out = [intent]
        if intent.kind == "put" and intent.obj not in (ctx.held, HELD):
            out = [Intent("take", intent.clause, obj=intent.obj, hand=intent.hand), intent]
        if intent.kind == "bring" and intent.obj in (ctx.held, HELD):  # in the hand: go and put it
            out = [Intent("go", intent.clause, obj=intent.place), replace(intent, kind="put")]
        for i in out:
            if i.kind == "take":
                ctx.held, ctx.last = i.obj, i.obj
            elif i.kind == "bring" or i.kind == "put":
                ctx.held, ctx.last, ctx.last_place = "", i.obj, i.place
            elif i.kind == "release":
                ctx.held = ""
            elif i.kind == "go":
                ctx.last_place, ctx.last = i.obj, i.obj
            elif i.kind in ("look", "find"):
                ctx.last = i.obj
        return out

    def _steps(self, intent: Intent) -> list[Step]:
        hand = intent.hand or self.hand
        if intent.kind == "take":
            return [
                _step("localize", intent.obj),
                _step("reach", hand, intent.obj),
                Step(line=0, action="grasp", args=(hand,), bind=HELD),
            ]
        if intent.kind == "bring":
            return [
                *self._steps(replace(intent, kind="take")),
                *self._steps(Intent("go", intent.clause, obj=intent.place)),
                _step("put", intent.obj, on=intent.place),
            ]
        if intent.kind == "go":
            return [_step("localize", intent.obj), _step("goto", intent.obj)]
        if intent.kind == "put":
            return [_step("localize", intent.place), _step("put", intent.obj, on=intent.place)]
        if intent.kind == "release":
            return [_step("open", hand)]
        if intent.kind == "look":
            return [_step("look_at", intent.obj)]
        if intent.kind == "find":
            return [_step("localize", intent.obj)]
        if intent.kind == "turn":
            return [_step("turn", f"{intent.angle_deg:g}")]
        if intent.kind == "walk":
            return [_step("walk", f"{intent.forward_m:g}", f"{intent.left_m:g}")]
        if intent.kind == "stand":
            return [_step("stand_up")]
        raise NotUnderstoodError(intent.clause, f"no steps for {intent.kind}")


def _step(action: str, *args: str, **kwargs: str) -> Step:
    return Step(line=0, action=action, args=args, kwargs=dict(kwargs))
